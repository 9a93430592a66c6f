"""`--render KEY=VALUE` and `--camera KEY=VALUE`: any render or camera key
from the command line, checked as in the file, for render, animate, bench
and view; mistakes are usage errors naming the option."""
import textwrap

import OpenImageIO as oiio
import pytest

from fractalc.cli import main

pytestmark = pytest.mark.check

SCENE = textwrap.dedent("""\
    scene sphere(1)
    camera { position: (0, -4, 1), target: (0, 0, 0), fov: 40 }
    render { width: 16, height: 12, ao: 0.2, max_steps: 200 }
    path {
        0: { position: (0, -4, 1) }
        1: { position: (4, 0, 1) }
    }
    """)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "ball.frac"
    path.write_text(SCENE)
    return path


def exit_code(argv) -> int:
    try:
        return main(argv)
    except SystemExit as stop:      # argparse's own usage errors
        return stop.code


def metadata(path) -> dict:
    image = oiio.ImageInput.open(str(path))
    spec = image.spec()
    image.close()
    return {a.name.removeprefix("fractalc:"): a.value for a in spec.extra_attribs if a.name.startswith("fractalc:")}


@pytest.mark.opencl
def test_render_takes_render_and_camera_keys(scene_file, tmp_path):
    out = tmp_path / "out.exr"
    assert main(["render", str(scene_file), "-o", str(out), "-q", "--render", "ao=0.5", "--render",
                 "max_steps=512", "--render", "fog.density=0.1", "--camera", "fov=30",
                 "--camera", "position=1,-4,2"]) == 0
    found = metadata(out)
    assert found["render.ao"] == "0.5" and found["render.max_steps"] == "512"
    assert "density=0.1" in found["render.fog"]
    assert found["camera.fov"] == "30" and found["camera.position"] == "1 -4 2"
    assert found["camera.target"] == "0 0 0"      # keys not given stay the file's


@pytest.mark.opencl
def test_keys_change_the_picture(scene_file, tmp_path):
    plain, narrow = tmp_path / "plain.exr", tmp_path / "narrow.exr"
    assert main(["render", str(scene_file), "-o", str(plain), "-q"]) == 0
    assert main(["render", str(scene_file), "-o", str(narrow), "-q", "--camera", "fov=20"]) == 0
    coverage = [oiio.ImageBuf(str(p)).get_pixels(oiio.FLOAT)[..., 3].mean() for p in (plain, narrow)]
    assert coverage[1] > coverage[0] * 2     # a narrower view: the ball fills more of it


@pytest.mark.parametrize("args, message", [
    (["--render", "ao=2"], "--render ao=2: 'ao' of 'render' must be between 0 and 1, not 2"),
    (["--render", "foo=1"], "--render foo=1: 'render' has no key 'foo' (known: width, height"),
    (["--render", "ao"], "--render takes KEY=VALUE, not 'ao'"),
    (["--render", "max_steps=1.5"], "--render max_steps=1.5: 'max_steps' of 'render' must be a whole number"),
    (["--render", "normals=sideways"], "--render normals=sideways: 'normals' must be 'tetrahedral' or 'central'"),
    (["--render", "background=1,2"], "--render background=1,2: 'background' must have 3 components"),
    (["--render", "fog.colour=1,0,0"], "--render fog.colour=1,0,0: 'fog' has no key 'colour'"),
    (["--camera", "fov=200"], "--camera fov=200: 'fov' of 'camera' must be less than 180, not 200"),
    (["--camera", "up=0,0,0"], "--camera up=0,0,0: 'up' of 'camera' must not be zero"),
    (["--camera", "zoom=2"], "--camera zoom=2: 'camera' has no key 'zoom' (known: position, target"),
    (["--camera", "target=0,-4,1"], "--camera: the camera's 'target' is its 'position'"),
])
@pytest.mark.parametrize("command", ["render", "animate", "bench"])
def test_mistakes_are_usage_errors_naming_the_option(scene_file, tmp_path, capsys, command, args, message):
    output = {"render": ["-o", str(tmp_path / "out.png")], "animate": ["-o", str(tmp_path / "f%02d.png")],
              "bench": ["--frames", "1"]}[command]
    assert exit_code([command, str(scene_file), *output, *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "ball.frac:1" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ball.frac"]


@pytest.mark.parametrize("command", ["check", "render", "compile", "animate", "bench", "view"])
def test_an_unknown_param_is_a_command_line_mistake(tmp_path, capsys, command):
    """`--set powr=5` was reported at the scene file's 1:1 (issue 21): it is
    the command line's mistake, in one line, with the closest param."""
    path = tmp_path / "bulb.frac"
    path.write_text("param power = 8 in [2, 16]\n" + SCENE.replace("sphere(1)", "sphere(power / 8)"))
    output = {"render": ["-o", str(tmp_path / "out.png")], "compile": ["-o", str(tmp_path / "out.cl")],
              "animate": ["-o", str(tmp_path / "f%02d.png")], "bench": ["--frames", "1"]}.get(command, [])
    assert exit_code([command, str(path), *output, "--set", "power=4", "--set", "powr=5"]) == 2
    assert capsys.readouterr().err == ("fractalc: error: --set powr=5: the scene has no param 'powr'; "
                                       "did you mean 'power'?\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bulb.frac"]
    assert exit_code([command, str(tmp_path / "bulb.frac"), *output, "--set", "x=1"]) == 2
    assert "--set x=1: the scene has no param 'x' (its params: power)" in capsys.readouterr().err


@pytest.mark.opencl
def test_animate_frames_take_the_keys(scene_file, tmp_path):
    pattern = str(tmp_path / "frames" / "f%02d.exr")
    assert main(["animate", str(scene_file), "-o", pattern, "--fps", "1", "-q"]) == 0
    # frames on disk made with other keys are rendered again, not kept
    for keys in (["--camera", "fov=25"], ["--camera", "fov=25", "--render", "ao=0.9"]):
        assert main(["animate", str(scene_file), "-o", pattern, "--fps", "1", "-q", *keys]) == 0
        for index in (0, 1):
            found = metadata(pattern % index)
            assert found["camera.fov"] == "25" and found["render.ao"] == ("0.9" if "ao=0.9" in keys else "0.2")
    # the path still moves the camera: position is the path's
    assert metadata(pattern % 1)["camera.position"] == "4 0 1"


def test_bench_renders_with_the_keys(scene_file, monkeypatch, capsys):
    import fractalc.bench
    seen = {}

    def bench(scene, **options):
        seen["render"], seen["camera"] = scene.checked.render, scene.checked.camera
        raise SystemExit(0)
    monkeypatch.setattr(fractalc.bench, "bench", bench)
    assert exit_code(["bench", str(scene_file), "--frames", "1", "--render", "max_steps=64",
                      "--camera", "fov=60"]) == 0
    assert seen["render"].max_steps == 64 and seen["camera"].fov == 60.0


def test_view_opens_on_the_keys(scene_file, monkeypatch):
    view = pytest.importorskip("fractalc.view")
    shown = {}
    monkeypatch.setattr(view, "show", lambda viewer: shown.update(camera=viewer.lens,
                                                                  render=viewer.scene.checked.render))
    assert main(["view", str(scene_file), "--render", "ao=0.7", "--camera", "fov=35"]) == 0
    assert shown["camera"].fov == 35.0 and shown["render"].ao == 0.7


def test_view_checks_keys_before_opening(scene_file, monkeypatch, capsys):
    view = pytest.importorskip("fractalc.view")
    monkeypatch.setattr(view, "Viewer", lambda *a, **k: pytest.fail("the viewer opened"))
    assert main(["view", str(scene_file), "--camera", "fov=0"]) == 2
    assert "--camera fov=0: 'fov' of 'camera' must be greater than 0" in capsys.readouterr().err
