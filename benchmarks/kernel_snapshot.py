"""The kernels fractalc emits, as a snapshot to compare before and after a
change that must not change them (a restructuring):

    python benchmarks/kernel_snapshot.py write before.json [--sources DIR]
    ... change the code ...
    python benchmarks/kernel_snapshot.py write after.json
    python benchmarks/kernel_snapshot.py compare before.json after.json [--sources DIR]

A snapshot holds the sha256 of each kernel source for: every .frac file
under examples/ and tests/, each library formula in a scene of its own,
and every scene the test suite loads (the corpus tests/conftest.py records
with FRACTALC_RECORD_SCENES=FILE: `FRACTALC_RECORD_SCENES=scenes.jsonl
python -m pytest -q -n 0`; pass it with --corpus), each at four targets
(16 lanes and 1 lane, float and double; `fast_math` as a device with exact
native functions would have it, and as one without; the recorded scenes at
16 lanes in float and 1 lane in double), as render programs and as the
estimate's own programs (emit_distance). Emitting needs no OpenCL device;
`--jobs N` emits in N processes. `compare` lists every name whose kernel
differs, with the first differing lines when the sources were kept.
"""
from __future__ import annotations

import argparse
import difflib
import hashlib
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# this checkout's fractalc, not one installed in the environment (which the
# script's folder on sys.path would otherwise import: a snapshot of that)
sys.path.insert(0, str(ROOT))
TARGETS = {"16f": dict(lanes=16, double=False), "1f": dict(lanes=1, double=False),
           "16d": dict(lanes=16, double=True), "1d": dict(lanes=1, double=True)}


def scenes(corpus: Path | None):
    """(name, text, path, targets) of every scene of the snapshot."""
    for path in sorted(list(ROOT.glob("examples/**/*.frac")) + list(ROOT.glob("tests/**/*.frac"))):
        yield str(path.relative_to(ROOT)), path.read_text(), str(path), FULL
    library = (ROOT / "stdlib_frac/formulas.frac").read_text()
    for name in re.findall(r"^formula (\w+)", library, re.MULTILINE):
        yield f"library formula {name}", f"scene fractal({name}(), iterations: 8, bound: 4)", "<string>", FULL
    if corpus is not None:
        seen = set()
        for line in corpus.read_text().splitlines():
            entry = json.loads(line)
            key = (entry["text"], entry["path"])
            if key not in seen:
                seen.add(key)
                digest = hashlib.sha256(repr(key).encode()).hexdigest()[:12]
                yield f"test scene {digest}", entry["text"], entry["path"], RECORDED


FULL = tuple((name, exact) for name in TARGETS for exact in (True, False))
RECORDED = (("16f", False), ("1d", False))


def scene_kernels(item) -> list[tuple[str, str]]:
    """(name, source) of one scene's kernels; a scene that no longer checks
    is recorded as its error."""
    from dataclasses import replace
    import fractalc
    from fractalc.emit import Target, emit, emit_distance
    from fractalc.lower import lower
    name, text, path, targets = item
    try:
        scene = fractalc.loads(text, path=path)
    except Exception as error:      # a scene of the corpus that is meant to fail
        return [(name, f"error: {error}")]
    out = []
    lowered = {}
    for target_name, exact in targets:
        target = TARGETS[target_name]
        precision = "double" if target["double"] else "float"
        if precision not in lowered:
            checked = replace(scene.checked, render=replace(scene.checked.render, precision=precision))
            lowered[precision] = lower(checked)
        kind = f"{target_name}{'' if exact else ' inexact native'}"
        try:
            out.append((f"{name} [{kind}]", emit(lowered[precision], Target(exact_native=exact, **target))))
            out.append((f"{name} [{kind} distance]",
                        emit_distance(lowered[precision], Target(exact_native=exact, **target))))
        except Exception as error:      # an emitter failure is a difference worth seeing
            out.append((f"{name} [{kind}]", f"error: {type(error).__name__}: {error}"))
    return out


def kernels(corpus: Path | None, jobs: int = 1):
    items = list(scenes(corpus))
    if jobs > 1:
        import multiprocessing
        with multiprocessing.Pool(jobs) as pool:
            for found in pool.imap(scene_kernels, items, chunksize=16):
                yield from found
    else:
        for item in items:
            yield from scene_kernels(item)


def write(out: Path, corpus: Path | None, sources: Path | None, jobs: int) -> int:
    snapshot = {}
    for name, source in kernels(corpus, jobs):
        digest = hashlib.sha256(source.encode()).hexdigest()
        snapshot[name] = digest
        if sources is not None:
            sources.mkdir(parents=True, exist_ok=True)
            (sources / f"{digest}.cl").write_text(source)
    out.write_text(json.dumps(snapshot, indent=1, sort_keys=True))
    print(f"{len(snapshot)} kernels ({len(set(snapshot.values()))} distinct) -> {out}")
    return 0


def compare(before: Path, after: Path, sources: Path | None) -> int:
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    changed = [name for name in sorted(set(a) & set(b)) if a[name] != b[name]]
    for name in changed:
        print(f"differs: {name}")
        if sources is not None and (sources / f"{a[name]}.cl").exists() and (sources / f"{b[name]}.cl").exists():
            diff = difflib.unified_diff((sources / f"{a[name]}.cl").read_text().splitlines(),
                                        (sources / f"{b[name]}.cl").read_text().splitlines(), lineterm="", n=1)
            print("\n".join(list(diff)[:40]))
    for name in sorted(set(a) - set(b)):
        print(f"only before: {name}")
    for name in sorted(set(b) - set(a)):
        print(f"only after: {name}")
    same = len(set(a) & set(b)) - len(changed)
    print(f"{same} identical, {len(changed)} differ, {len(set(a) - set(b))} only before, "
          f"{len(set(b) - set(a))} only after")
    return 1 if changed else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    writing = commands.add_parser("write")
    writing.add_argument("out", type=Path)
    writing.add_argument("--corpus", type=Path, help="scenes recorded from the test suite (JSON lines)")
    writing.add_argument("--sources", type=Path, help="keep each kernel's source here, by its sha256")
    writing.add_argument("--jobs", type=int, default=1, help="emit in this many processes")
    comparing = commands.add_parser("compare")
    comparing.add_argument("before", type=Path)
    comparing.add_argument("after", type=Path)
    comparing.add_argument("--sources", type=Path)
    args = parser.parse_args()
    if args.command == "write":
        return write(args.out, args.corpus, args.sources, args.jobs)
    return compare(args.before, args.after, args.sources)


if __name__ == "__main__":
    sys.exit(main())
