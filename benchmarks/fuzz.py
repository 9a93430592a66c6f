"""The long fuzzing run (issues 10 and 22); tests/test_fuzz.py is its one-minute form.

    python benchmarks/fuzz.py --minutes 10 --seed 1 [--build-every 20] [--out fuzz-failures]
    python benchmarks/fuzz.py --seed 1 --case 123      # replay one case, print it and its verdict
    python benchmarks/fuzz.py --calls --minutes 10 --seed 1   # command lines and API calls
    python benchmarks/fuzz.py --calls --seed 1 --case 123

With --calls: generated command lines and API calls (tests/fuzz_calls.py),
each in a forked process under an address-space limit (--headroom MiB beyond
the server's own); the counts (tried, answered, failed) as it goes and at the
end, and the first case of each kind of failure in OUT/calls-NNN.txt.

Judges cases seed:0, seed:1, ... (tests/fuzz_scenes.py): every case is
checked; every `--build-every`-th one that checks is also built and rendered
16x12. Prints the counts (tried, checked, rejected, rendered, failures) as it
goes and at the end. The first failure of each kind (`fuzz_scenes.signature`)
is shrunk to a small repro, written to OUT/NNN.frac with OUT/NNN.txt saying what
failed; later ones of the same kind are only counted.
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import fuzz_calls  # noqa: E402
import fuzz_scenes  # noqa: E402


EXPECTATIONS = ("defect not reported", "valid scene rejected")
CHECKING = ("misplaced error", "traceback while checking", "hang while checking", *EXPECTATIONS)


def replay(seed: int, index: int, build: bool) -> None:
    case = fuzz_scenes.case(seed, index)
    print(f"# case {index} of seed {seed}: {case.origin} (expected: {case.expect}, defect at {case.where})")
    print(case.source if isinstance(case.source, str) else repr(case.source))
    verdict = fuzz_scenes.judge(case, build=build)
    print(f"# verdict: {verdict.outcome} {verdict.failure}\n{verdict.detail}")


def write_repro(out: Path, number: int, case, verdict, shrunk, seed: int, index: int) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"{number:03d}"
    stem.with_suffix(".frac").write_bytes(shrunk.source if isinstance(shrunk.source, bytes)
                                          else shrunk.source.encode())
    stem.with_suffix(".txt").write_text(
        f"{fuzz_scenes.signature(verdict)}\nseed {seed}, case {index}: {case.origin}\n"
        f"replay: python benchmarks/fuzz.py --seed {seed} --case {index}\n\n{verdict.detail}\n")
    return stem.with_suffix(".frac")


def run_calls(args) -> int:
    """The --calls mode: command lines and API calls until the deadline."""
    with fuzz_calls.Runner(args.headroom * 2 ** 20) as runner:
        if args.case is not None:
            case = fuzz_calls.case(args.seed, args.case)
            verdict = runner.judge(case)
            print(f"# case {args.case} of seed {args.seed}: {case}\n# verdict: {verdict.outcome} "
                  f"{verdict.failure}\n{verdict.detail}")
            return 0
        counts, kinds = collections.Counter(), {}
        deadline, last_print, index = time.monotonic() + args.minutes * 60, time.monotonic(), 0
        while time.monotonic() < deadline:
            case = fuzz_calls.case(args.seed, index)
            verdict = runner.judge(case)
            counts["tried"] += 1
            counts[f"{case.kind} {verdict.outcome}"] += 1
            if verdict.failure:
                kind = fuzz_calls.signature(case, verdict)
                kinds[kind] = kinds.get(kind, 0) + 1
                if kinds[kind] == 1:
                    args.out.mkdir(parents=True, exist_ok=True)
                    path = args.out / f"calls-{len(kinds):03d}.txt"
                    path.write_text(f"{kind}\nseed {args.seed}, case {index}: {case}\nreplay: python "
                                    f"benchmarks/fuzz.py --calls --seed {args.seed} --case {index}\n\n"
                                    f"{verdict.detail}\n")
                    print(f"NEW {path}: {kind} (case {index})", flush=True)
            index += 1
            if time.monotonic() - last_print > 30:
                last_print = time.monotonic()
                print(f"{dict(counts)}, {len(kinds)} kinds of failure", flush=True)
    print(f"calls, seed {args.seed}, {args.minutes:g} min: {dict(counts)} ({len(kinds)} kinds of failure)")
    for kind, n in sorted(kinds.items(), key=lambda item: -item[1]):
        print(f"{n:6d}  {kind}")
    return 1 if kinds else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--build-every", type=int, default=10, metavar="N",
                        help="build and render every N-th case that checks (0: never)")
    parser.add_argument("--out", type=Path, default=Path("fuzz-failures"))
    parser.add_argument("--case", type=int, help="replay this one case and stop")
    parser.add_argument("--calls", action="store_true", help="command lines and API calls instead of scenes")
    parser.add_argument("--headroom", type=int, default=fuzz_calls.HEADROOM_BYTES // 2 ** 20, metavar="MIB",
                        help="with --calls: address space a case may add to the server's (MiB)")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")     # the OpenCL compiler's chatter
    if args.calls:
        return run_calls(args)
    if args.case is not None:
        replay(args.seed, args.case, build=args.build_every != 0)
        return 0

    counts = collections.Counter()
    kinds: dict[str, int] = {}          # failure signature -> how many
    deadline = time.monotonic() + args.minutes * 60
    last_print = time.monotonic()
    index = 0
    while time.monotonic() < deadline:
        case = fuzz_scenes.case(args.seed, index)
        verdict = fuzz_scenes.judge(case, build=False)
        counts["tried"] += 1
        counts[verdict.outcome] += 1      # checked, rejected or failed
        if verdict.outcome == "checked" and args.build_every and (counts["checked"] - 1) % args.build_every == 0:
            verdict = fuzz_scenes.judge(case, build=True)
            counts["built"] += 1
            counts[verdict.outcome] += 1  # rendered or failed
        if verdict.failure:
            kind = fuzz_scenes.signature(verdict)
            kinds[kind] = kinds.get(kind, 0) + 1
            if kinds[kind] == 1:
                # failures of an expectation (where the defect is, valid or not) keep the generated scene
                expected = verdict.failure in EXPECTATIONS or case.where
                built = verdict.failure not in CHECKING
                shrunk = case if expected else fuzz_scenes.shrink(case, verdict, build=built,
                                                                    tries=60 if built else 400)
                path = write_repro(args.out, len(kinds), case, verdict, shrunk, args.seed, index)
                print(f"NEW {path}: {kind} (case {index})", flush=True)
        index += 1
        if time.monotonic() - last_print > 30:
            last_print = time.monotonic()
            print(f"{dict(counts)}, {len(kinds)} kinds of failure", flush=True)
    print(f"seed {args.seed}, {args.minutes:g} min: tried {counts['tried']}, checked {counts['checked']}, "
          f"rejected {counts['rejected']}, built {counts['built']}, rendered {counts['rendered']}, "
          f"failed {counts['failed']} ({len(kinds)} kinds)")
    for kind, n in sorted(kinds.items(), key=lambda item: -item[1]):
        print(f"{n:6d}  {kind}")
    return 1 if kinds else 0


if __name__ == "__main__":
    sys.exit(main())
