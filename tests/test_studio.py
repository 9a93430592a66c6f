"""fractalc studio in a real browser: headless Chromium (Debian's
`chromium`) driven by Playwright, on a studio server in a child process.
One server and one browser per test process; each test leaves the page in
a state the others accept. Skipped where Chromium or Playwright is
missing (see studio_harness.py for what to install).

With FRACTALC_STUDIO_SCREENSHOTS=FOLDER, `test_screenshots_for_the_docs`
saves the screenshots of docs/studio.md there.
"""
import difflib
import http.client
import io
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from fractalc.check import check
from fractalc.parse import parse
from studio_harness import REPO, Browser, StudioProcess, browser_missing

pytest.importorskip("tornado")
pytest.importorskip("PIL")
from PIL import Image  # noqa: E402

WAIT_MS = 60000

SCENE = """\
# A scene for the studio's tests: comments and layout stay as written.
param blend = 0.25 in [0, 1]     # how far the spheres melt together
param size = 0.6 in [0.2, 1.5]

material red { color: (0.8, 0.2, 0.1), specular: 0.3 }

scene union(sphere(size).translate((-0.5, 0, 0)),
            sphere(0.5).translate((0.5, 0, 0)), smooth: blend).material(red)
      | plane(offset: -0.6)

camera {
    position: (0, -4, 1.5),    # in front, a little above
    target: (0, 0, 0),
    fov: 40
}

light directional { direction: (-0.4, 0.6, -1), shadows: hard }

render { width: 64, height: 48, max_steps: 96, ao: 0.5 }
"""


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    folder = tmp_path_factory.mktemp("studio")
    scene = folder / "scene.frac"
    scene.write_text(SCENE)
    server = StudioProcess(scene, "--live-size", "64x48", "--preview-scale", "1", "--max-samples", "2")
    server.scene = scene
    yield server
    server.stop()


@pytest.fixture(scope="module")
def page(studio):
    reason = browser_missing()
    if reason:
        pytest.skip(reason)
    browser = Browser()
    page = browser.open(studio.url)
    page.wait_for_function("window.studio && studio.frames > 0", timeout=WAIT_MS)
    yield page
    assert not browser.errors, browser.errors
    browser.close()


def settled(page) -> dict:
    """The last frame once the view the page asked for last is refined
    (2 samples: the server's --max-samples)."""
    page.wait_for_function("studio.lastFrame && studio.lastFrame.seq === studio.seq "
                           "&& studio.lastFrame.samples === 2 && !studio.building", timeout=WAIT_MS)
    return page.evaluate("studio.lastFrame")


def canvas_pixels(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.locator("#image").screenshot())).convert("RGB"), dtype=float)


@pytest.mark.opencl
def test_the_page_shows_an_image(page):
    frame = settled(page)
    assert (frame["width"], frame["height"]) == (64, 48)
    pixels = canvas_pixels(page)
    assert pixels.std() > 10           # a picture (sphere, floor, sky), not one colour


@pytest.mark.opencl
def test_moving_a_slider_changes_the_image_without_a_rebuild(page):
    before = settled(page)
    value = page.locator("#param-blend-range").input_value()
    page.locator("#param-blend-range").fill("0.9" if float(value) < 0.5 else "0.1")
    page.wait_for_function(f"studio.seq > {before['seq']}")
    after = settled(page)
    assert after["digest"] != before["digest"]
    assert after["builds"] == before["builds"]


def _type_at(page, after: str, typed: str) -> None:
    """Put the cursor just after the text `after` in the editor and type."""
    page.locator("#editor textarea").click()
    page.evaluate("""(after) => { const t = document.querySelector('#editor textarea');
                     const i = t.value.indexOf(after) + after.length; t.setSelectionRange(i, i); }""", after)
    page.keyboard.type(typed)


@pytest.mark.opencl
def test_a_typed_mistake_is_marked_at_its_line_and_fixing_it_brings_the_image_back(page):
    settled(page)
    _type_at(page, "plane(offset: -0.6", ", colour: 2")       # line 9: plane has no 'colour'
    marker = page.wait_for_selector("#editor .marker", timeout=WAIT_MS)
    assert marker.get_attribute("data-line") == "9"
    item = page.locator("#diagnostics li").first.inner_text()
    assert "scene.frac:9:" in item and "'plane' has no argument 'colour'" in item
    assert not page.locator("#note").is_hidden()
    frames = page.evaluate("studio.frames")
    for _ in ", colour: 2":
        page.keyboard.press("Backspace")
    page.wait_for_function(f"studio.diagnostics.length === 0 && studio.frames > {frames}", timeout=WAIT_MS)
    assert page.locator("#editor .marker").count() == 0
    settled(page)
    assert page.locator("#note").is_hidden()


def _only_literals_differ(before: str, after: str) -> bool:
    """Whether the lines of `after` are those of `before` with numbers changed."""
    numbers = re.compile(r"-?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
    old, new = before.splitlines(), after.splitlines()
    return len(old) == len(new) and all(numbers.sub("#", a) == numbers.sub("#", b) for a, b in zip(old, new))


@pytest.mark.opencl
def test_a_keyframe_and_saving_write_a_path_block(page, studio):
    settled(page)
    page.locator("#time").fill("0")
    page.locator("#key-add").click()
    page.wait_for_function("studio.keyframes.length === 1")
    page.locator("#time").fill("2")
    box = page.locator("#image").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 60, y + 5, steps=4)          # orbit
    page.mouse.up()
    page.wait_for_function("Math.abs(studio.camera.position[0]) > 0.5")
    page.locator("#key-add").click()
    page.wait_for_function("studio.keyframes.length === 2")
    page.locator("#save").click()
    page.wait_for_function("studio.notices.some(n => n.text.startsWith('saved'))", timeout=WAIT_MS)
    saved = studio.scene.read_text()
    checked = check(parse(saved, "scene.frac"))
    assert [k.time for k in checked.path.keyframes] == [0.0, 2.0]
    assert abs(checked.path.keyframes[1].position[0]) > 0.5
    # the rest of the file: the same lines, at most with other numbers
    path_start = saved.index("path {")
    path_end = saved.index("\n}\n", path_start) + 3        # the line that closes the block
    rest = saved[:path_start] + saved[path_end:]
    assert _only_literals_differ(SCENE, rest), "".join(difflib.unified_diff(SCENE.splitlines(True),
                                                                           rest.splitlines(True)))
    assert "# in front, a little above" in rest
    page.wait_for_function("!Object.values(studio.dirty).some(v => v === true)")


@pytest.mark.opencl
def test_a_flood_of_changes_renders_the_newest_only(page):
    settled(page)
    frames = page.evaluate("studio.frames")
    last = page.evaluate("""() => {
        for (let i = 0; i < 3000; i++) {
            studio.seq += 1;
            studio.send({type: "view", seq: studio.seq, params: {size: 0.3 + (i % 100) / 100}});
        }
        return studio.seq; }""")
    frame = settled(page)
    assert frame["seq"] == last
    # a preview and a refined image for the few views the renderer got to
    assert page.evaluate("studio.frames") - frames < 100


@pytest.mark.opencl
def test_a_change_of_the_file_on_disk_reloads_the_page(page, studio):
    settled(page)
    page.wait_for_function("!studio.dirty.text")
    text = studio.scene.read_text()
    studio.scene.write_text(text.replace("param size = 0.6", "param size = 0.7"))
    page.wait_for_function("studio.editor.text.includes('param size = 0.7')", timeout=WAIT_MS)
    page.wait_for_function("document.getElementById('param-size').value === '0.7'", timeout=WAIT_MS)
    # with edits of its own, the page asks
    _type_at(page, "# A scene", " (edited)")
    page.wait_for_function("studio.dirty.text", timeout=WAIT_MS)
    studio.scene.write_text(text)
    page.wait_for_selector("#banner:not([hidden])", timeout=WAIT_MS)
    assert "(edited)" in page.evaluate("studio.editor.text")
    page.locator("#reload").click()
    page.wait_for_function("studio.editor.text.includes('param size = 0.6') && !studio.dirty.text", timeout=WAIT_MS)


def _read(path) -> np.ndarray:
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(str(path))
    pixels = np.asarray(image.read_image(oiio.FLOAT))
    image.close()
    return pixels


@pytest.mark.opencl
def test_a_final_render_writes_what_its_command_line_renders(page, studio, tmp_path):
    settled(page)
    page.locator("#param-size-range").fill("0.9")         # a live value: --set on the command line
    output = tmp_path / "still.exr"
    page.locator("#output").fill(str(output))
    page.locator("#final-width").fill("16")
    page.locator("#final-height").fill("12")
    page.locator("#final-samples").fill("2")
    page.locator("#render-still").click()
    page.wait_for_function("studio.job && studio.job.state === 'done'", timeout=WAIT_MS)
    command = page.locator("#render-command").inner_text()
    assert command.startswith(f"fractalc render {studio.scene} -o {output} ")
    assert re.search(r" --set size=0\.89\d*( |$)", command)     # the slider's step near 0.9
    words = command.split()
    again = tmp_path / "again.exr"
    words[words.index("-o") + 1] = str(again)
    done = subprocess.run([sys.executable, "-m", "fractalc", *words[1:], "-q"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert np.array_equal(_read(output), _read(again))


@pytest.mark.opencl
def test_a_final_render_can_be_cancelled(page, tmp_path):
    settled(page)
    if page.evaluate("studio.keyframes.length") < 2:
        for time_ in ("0", "1"):
            page.locator("#time").fill(time_)
            page.locator("#key-add").click()
        page.wait_for_function("studio.keyframes.length >= 2")
    pattern = tmp_path / "frames" / "f_%05d.png"
    page.locator("#frames-output").fill(str(pattern))
    page.locator("#final-fps").fill("1000")              # a thousand frames or more
    page.locator("#final-width").fill("8")
    page.locator("#final-height").fill("8")
    page.locator("#render-animation").click()
    page.wait_for_function("studio.job && studio.job.state === 'running' && studio.job.progress > 0",
                           timeout=WAIT_MS)
    page.locator("#render-cancel").click()
    page.wait_for_function("studio.job.state === 'cancelled'", timeout=WAIT_MS)
    written = list((tmp_path / "frames").iterdir())
    assert 0 < len(written) < 1000
    assert all(f.name.startswith("f_") and f.suffix == ".png" for f in written)    # no partial file


def _request(studio, path: str, headers: dict) -> int:
    connection = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=10)
    try:
        connection.request("GET", path, headers={"Host": f"127.0.0.1:{studio.port}", **headers})
        return connection.getresponse().status
    finally:
        connection.close()


WEBSOCKET = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
             "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}


def test_requests_without_the_token_or_from_another_site_are_refused(studio):
    token = f"?token={studio.token}"
    own = {"Origin": f"http://127.0.0.1:{studio.port}"}
    assert _request(studio, "/" + token, own) == 200
    assert _request(studio, "/", own) == 403
    assert _request(studio, "/?token=wrong", own) == 403
    assert _request(studio, "/static/studio.js", own) == 403
    assert _request(studio, "/" + token, {"Origin": "http://evil.example"}) == 403
    # DNS rebinding: another site's name, resolved to this machine
    assert _request(studio, "/" + token, {"Host": f"evil.example:{studio.port}"}) == 403
    assert _request(studio, "/socket" + token, {**WEBSOCKET, **own}) == 101
    assert _request(studio, "/socket", {**WEBSOCKET, **own}) == 403
    assert _request(studio, "/socket" + token, {**WEBSOCKET, "Origin": "http://evil.example"}) == 403


@pytest.mark.opencl
def test_saving_a_file_with_crlf_line_breaks_keeps_them(tmp_path):
    """The session alone (no server, no browser): a live param saved into a
    Windows file changes that literal, and every line break stays CRLF."""
    import threading
    from fractalc.studio.session import Options, Studio
    path = tmp_path / "windows.frac"
    path.write_bytes(SCENE.replace("\n", "\r\n").encode())
    calls, sent, lock = [], [], threading.Lock()

    def call_soon(function, *args):
        with lock:
            calls.append((function, args))

    def run_until(done):      # the event loop's part: what the live thread calls back
        deadline = time.monotonic() + 60
        while not done() and time.monotonic() < deadline:
            with lock:
                ready, calls[:] = list(calls), []
            for function, args in ready:
                function(*args)
            time.sleep(0.01)

    studio = Studio(str(path), Options(live_size=(16, 12)), sent.append, call_soon)
    try:
        run_until(lambda: studio.checked is not None)
        studio.receive({"type": "view", "seq": 1, "params": {"blend": 0.5}})
        # the page's text, as a text area has it: "\n" line breaks
        studio.receive({"type": "text", "text": SCENE + "# the end\n"})
        run_until(lambda: studio.checked_version == studio.version)
        studio.receive({"type": "save"})
    finally:
        studio.close()
    assert not [m for m in sent if isinstance(m, dict) and m["type"] == "notice" and m["error"]]
    saved = path.read_bytes().decode()
    assert saved == (SCENE + "# the end\n").replace("param blend = 0.25", "param blend = 0.5").replace("\n", "\r\n")


@pytest.mark.parametrize("arguments, says", [
    (["no-such.frac"], "cannot read no-such.frac: no such file"),
    (["scene.frac", "--live-size", "320"], "--live-size: '320' is not a size WIDTHxHEIGHT"),
])
def test_command_line_mistakes_are_usage_errors(tmp_path, arguments, says):
    (tmp_path / "scene.frac").write_text(SCENE)
    done = subprocess.run([sys.executable, "-m", "fractalc", "studio", *arguments, "--no-browser"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert done.returncode == 2 and says in done.stderr and "Traceback" not in done.stderr
    assert done.stdout == ""


@pytest.mark.skipif(not os.environ.get("FRACTALC_STUDIO_SCREENSHOTS"),
                    reason="FRACTALC_STUDIO_SCREENSHOTS=FOLDER takes the docs' screenshots")
@pytest.mark.opencl
def test_screenshots_for_the_docs(tmp_path):
    reason = browser_missing()
    if reason:
        pytest.skip(reason)
    folder = os.environ["FRACTALC_STUDIO_SCREENSHOTS"]
    scene = tmp_path / "csg.frac"
    scene.write_text((REPO / "examples" / "csg.frac").read_text())
    server = StudioProcess("csg.frac", "--max-samples", "16", cwd=tmp_path)
    browser = Browser(1400, 820)
    try:
        page = browser.open(server.url)
        page.wait_for_function("studio.frames > 0 && studio.lastFrame.samples >= 16", timeout=WAIT_MS * 3)
        page.screenshot(path=os.path.join(folder, "studio.png"))
        _type_at(page, "smooth: 0.05", " +")
        page.wait_for_selector("#editor .marker", timeout=WAIT_MS)
        page.get_by_text("Render", exact=True).click()
        page.get_by_text("Lights", exact=True).click()
        page.screenshot(path=os.path.join(folder, "studio-error.png"))
        assert not browser.errors, browser.errors
    finally:
        browser.close()
        server.stop()
