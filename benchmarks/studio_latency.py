"""fractalc studio's latency, measured by the test driver in the browser
(headless Chromium through Playwright, as tests/test_studio.py runs it):

- a slider move to the new image: from the slider's input event to the
  new view's first image drawn on the page, over --moves moves (each after
  the image before it and a pause: 0.1 s, as while a person drags it, and
  0.5 s, after which the studio is refining the image), at 320x180
  (--live-size 320x180 --preview-scale 1: the first image is full size,
  one sample);
- the first image after a text edit, from the page sending the text to the
  new scene's first image: cold (a new render setting, so a new kernel that
  no cache holds) and cached (back to a text built before).

    python benchmarks/studio_latency.py [--moves 50] [--edits 3] [SCENE ...]

Default scenes: examples/csg.frac and the shared bulb-640 scene. Prints a
Markdown table (docs/performance.md, "The studio").
"""
from __future__ import annotations

import argparse
import random
import re
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from studio_harness import Browser, StudioProcess, browser_missing  # noqa: E402

SCENES = [REPO / "examples" / "csg.frac", REPO.parent / "shared" / "bench" / "bulb-640.frac"]
# between an image and the next move: as while a person drags a slider
# (under the studio's 0.25 s before refining), and long enough that the
# studio is refining when the move comes
PAUSES = (0.1, 0.5)
PAUSE_SECONDS = 0.1       # after a text edit's image
WAIT_MS = 120000

MOVE = """async ([name, value]) => {
    const slider = document.getElementById(`param-${name}-range`);
    const seq = studio.seq;
    const start = performance.now();
    slider.value = value;
    slider.dispatchEvent(new Event("input"));
    await new Promise((resolve) => {
        const look = () => {
            if (studio.seq > seq && studio.lastFrame.seq === studio.seq) {
                window.removeEventListener("studioframe", look);
                resolve();
            }
        };
        window.addEventListener("studioframe", look);
    });
    return [studio.lastFrame.shownAt - start, studio.lastFrame.milliseconds];
}"""

EDIT = """async (text) => {
    const editor = studio.editor.textarea;
    const sent = studio.textSentAt;
    editor.value = text;
    editor.dispatchEvent(new Event("input"));
    await new Promise((resolve) => {
        const look = () => {
            if (studio.textSentAt > sent && studio.sceneAt > studio.textSentAt
                    && studio.lastFrame.shownAt > studio.sceneAt) {
                window.removeEventListener("studioframe", look);
                resolve();
            }
        };
        window.addEventListener("studioframe", look);
    });
    return [studio.lastFrame.shownAt - studio.textSentAt, studio.lastFrame.builds];
}"""


def percentile(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(p / 100 * (len(ordered) - 1)))]


def measure(scene: Path, moves: int, edits: int) -> dict:
    server = StudioProcess(scene, "--live-size", "320x180", "--preview-scale", "1")
    browser = Browser()
    try:
        page = browser.open(server.url)
        page.wait_for_function("studio.frames > 0 && studio.scene", timeout=WAIT_MS)
        param = page.evaluate("studio.scene.params.find((p) => p.low !== null && p.high !== null)")
        low, high = param["low"], param["high"]
        moves_at = {}
        for pause in PAUSES:
            latencies, renders = [], []
            for i in range(moves):
                value = low + (high - low) * (0.25 + 0.5 * (i % 2) + 0.01 * (i // 2) % 0.2)
                latency, render = page.evaluate(MOVE, [param["name"], value])
                latencies.append(latency)
                renders.append(render)
                time.sleep(pause)
            moves_at[pause] = (latencies, renders)
        original = page.evaluate("studio.editor.text")
        cold, cached = [], []
        for _ in range(edits):
            # a max_distance no cache has seen: a new kernel
            distance = f"max_distance: {random.uniform(30, 60):.6f}"
            edited = re.sub(r"max_distance: [0-9.]+", distance, original, count=1)
            assert edited != original, "the scene needs a max_distance in its render block"
            milliseconds, builds_after = page.evaluate(EDIT, edited)
            cold.append(milliseconds)
            time.sleep(PAUSE_SECONDS)
            cached.append(page.evaluate(EDIT, original)[0])       # built before
            time.sleep(PAUSE_SECONDS)
        device = page.evaluate("document.getElementById('device').textContent")
        assert not browser.errors, browser.errors
    finally:
        browser.close()
        server.stop()
    row = {"scene": scene.name, "cold": statistics.median(cold), "cached": statistics.median(cached),
           "moves": moves, "edits": edits, "device": device}
    for pause, (latencies, renders) in moves_at.items():
        row[pause] = (statistics.median(latencies), percentile(latencies, 95), statistics.median(renders))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", type=Path, default=SCENES)
    parser.add_argument("--moves", type=int, default=50)
    parser.add_argument("--edits", type=int, default=3)
    args = parser.parse_args()
    reason = browser_missing()
    if reason:
        sys.exit(f"studio_latency: {reason}")
    rows = [measure(scene, args.moves, args.edits) for scene in args.scenes]
    moving, paused = PAUSES
    print(f"| scene | slider to image, moves {moving:g} s apart: p50 | p95 | render alone (p50) "
          f"| moves {paused:g} s apart (refining): p50 | p95 | text edit, cold build | cached build |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['scene']} | {r[moving][0]:.0f} ms | {r[moving][1]:.0f} ms | {r[moving][2]:.0f} ms "
              f"| {r[paused][0]:.0f} ms | {r[paused][1]:.0f} ms | {r['cold']:.0f} ms | {r['cached']:.0f} ms |")
    print(f"\n{rows[0]['moves']} slider moves of each kind and {rows[0]['edits']} edits of each kind per scene, "
          f"at 320x180; device: {rows[0]['device']}")

if __name__ == "__main__":
    main()
