"""Fuzzing (issues 10 and 22): generated scenes and mutated example files,
generated command lines and API calls, for about a minute.

Every case that checks must build and render a 16x12 image with finite values
(Z is +inf on misses) and finite distances; every case that does not check must
raise a SceneError located inside the text (at the deliberate defect, for
generated ones), never another exception. The command line must answer
exit 2 with `FILE:LINE:COL: error:` and no traceback. Generated command lines
and API calls (tests/fuzz_calls.py), each under an address-space limit, must
answer in words: an exit code with an error line, or a result or
SceneError/ValueError/TypeError/RenderError; never a traceback, a crash or a
hang. The seed is fixed, so
a run is reproducible; a failure names the seed and case to replay with
`python benchmarks/fuzz.py --seed S --case I`. The longer run is that script.
"""
import re
import sys
import time
import warnings

import pytest

import fuzz_calls
import fuzz_scenes
from fractalc import cli

SEED = 20240610
# CI's share of the suite's 10 minutes (the suite measured 9:22 with 15/20/20);
# benchmarks/fuzz.py runs for as long as asked
FRONT_END_SECONDS = 10     # check only: thousands of cases
BUILD_SECONDS = 12         # each build costs 1-5 s on a 2-core CPU
MOST_BUILDS = 30
CLI_CASES = 40
CALL_SECONDS = 12          # command lines and API calls, each in a forked process under a memory limit


def report(seed: int, failures: list) -> str:
    lines = [f"{len(failures)} failing case(s), seed {seed}:"]
    for index, case, verdict in failures[:10]:
        lines.append(f"- case {index} ({case.origin}): {verdict.failure}: {verdict.detail[:400]}")
        lines.append(f"  replay: python benchmarks/fuzz.py --seed {seed} --case {index}")
    return "\n".join(lines)


def run(seed: int, seconds: float, build: bool, most: int):
    """Judge cases seed:0, seed:1, ... until the deadline (checked between
    cases) or `most` of them got as far as `build` asks."""
    deadline = time.monotonic() + seconds
    failures, outcomes, index = [], [], 0
    while time.monotonic() < deadline and sum(o in ("checked", "rendered") for o in outcomes) < most:
        case = fuzz_scenes.case(seed, index)
        if build and fuzz_scenes.judge(case, build=False).outcome != "checked":
            index += 1
            continue    # only scenes that check are worth a build here
        verdict = fuzz_scenes.judge(case, build=build)
        outcomes.append(verdict.outcome)
        if verdict.failure:
            failures.append((index, case, verdict))
        index += 1
    return outcomes, failures


def test_generated_and_mutated_scenes_check_or_fail_at_a_place():
    outcomes, failures = run(SEED, FRONT_END_SECONDS, build=False, most=10**9)
    assert not failures, report(SEED, failures)
    # enough of each kind for the run to mean something, even on a slow machine
    assert outcomes.count("checked") >= 50 and outcomes.count("rejected") >= 50, outcomes


@pytest.mark.opencl
def test_scenes_that_check_render_finite_images():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # the OpenCL compiler's chatter
        outcomes, failures = run(SEED + 1, BUILD_SECONDS, build=True, most=MOST_BUILDS)
    assert not failures, report(SEED + 1, failures)
    assert outcomes.count("rendered") >= 3, outcomes


@pytest.mark.parametrize("index", range(CLI_CASES))
def test_the_check_command_answers_like_the_api(index, tmp_path, capsys):
    case = fuzz_scenes.case(SEED + 2, index)
    path = tmp_path / "fuzz scene.frac"
    data = case.source if isinstance(case.source, bytes) else case.source.encode()
    path.write_bytes(data)
    verdict = fuzz_scenes.judge(case, build=False)
    status = cli.main(["check", str(path)])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    if verdict.outcome == "rejected":
        assert status == 2
        assert re.match(re.escape(str(path)) + r":\d+:\d+: error: \S", err), err
    elif verdict.outcome == "checked":
        # one line of what was checked; on stderr only notes (each with its quoted line and caret)
        assert status == 0 and out.startswith(f"{path}: ok: ") and out.count("\n") == 1, (out, err)
        headers = [line for line in err.splitlines() if not line.startswith("    ")]
        assert all(line.startswith(f"{path}:") and ": note: " in line for line in headers), err
    else:
        pytest.fail(report(SEED + 2, [(index, case, verdict)]))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forks under RLIMIT_AS as Linux counts it")
def test_command_lines_and_api_calls_answer_in_words_within_memory():
    deadline = time.monotonic() + CALL_SECONDS
    failures, tried = [], 0
    with warnings.catch_warnings(), fuzz_calls.Runner() as runner:
        warnings.simplefilter("ignore")
        while time.monotonic() < deadline:
            case = fuzz_calls.case(SEED + 3, tried)
            verdict = runner.judge(case)
            if verdict.failure:
                failures.append((tried, case, verdict))
            tried += 1
    assert not failures, "\n".join(
        f"- case {index}: {case}: {verdict.failure}: {verdict.detail[-600:]}\n"
        f"  replay: python benchmarks/fuzz.py --calls --seed {SEED + 3} --case {index}"
        for index, case, verdict in failures[:10])
    assert tried >= 5, tried      # enough to mean something on a loaded machine (about 2 s a case)
