"""The command line: `fractalc render` outputs (PNG, EXR channels and
metadata), `--set`, usage and runtime errors (exit codes, one-line causes,
no traceback, no partial or clobbered output), `--help`, `devices`,
`--device`, `--precision double` and `compile`."""

import hashlib
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fractalc

OpenImageIO = pytest.importorskip("OpenImageIO")
oiio = OpenImageIO

REPO = Path(__file__).resolve().parents[1]
W, H = 48, 36      # requested on the command line; the file says 64 x 48

SCENE = textwrap.dedent("""\
    # a sphere on a box, for the command-line tests
    param r = 1 in [0.5, 1.5]
    material red { color: (0.9, 0.2, 0.1), specular: 0.5, shininess: 20 }
    scene sphere(r).material(red) | box((2, 2, 0.4)).translate((0, 0, -1.2))
    camera { position: (0.5, -4, 1.5), target: (0, 0, -0.2), up: (0.1, 0, 1), fov: 40 }
    light directional { direction: (-0.4, 0.7, -1), shadows: soft }
    render { width: 64, height: 48, max_steps: 300, ao: 0.5, background: (0.1, 0.1, 0.2) }
    """)
CAMERA = dict(position=(0.5, -4, 1.5), target=(0, 0, -0.2), up=(0.1, 0, 1), fov=40)
EXR_CHANNELS = {"R", "G", "B", "A", "Z", "N.x", "N.y", "N.z", "steps"}


def fractalc_cli(*args, cwd, env=None):
    environment = {k: v for k, v in os.environ.items() if k != "FRACTALC_DEVICE"}
    environment["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    environment.update(env or {})
    return subprocess.run([sys.executable, "-m", "fractalc", *map(str, args)], cwd=cwd,
                          env=environment, capture_output=True, text=True, timeout=300)


def assert_clean_failure(result, code):
    assert result.returncode == code, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout
    assert "error:" in result.stderr


def read_image(path):
    """(pixels as float32 (H, W, C), channel names, spec) via OpenImageIO."""
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    spec = image.spec()
    pixels = image.read_image(oiio.FLOAT)
    image.close()
    return np.asarray(pixels), list(spec.channelnames), spec


def exr_planes(path):
    pixels, names, _ = read_image(path)
    return {name: pixels[..., i] for i, name in enumerate(names)}


STANDARD_ATTRIBUTES = re.compile(r"^(oiio:|openexr:|exr:|screenWindow|PixelAspectRatio|compression$|"
                                 r"DateTime$|Software$|Orientation$|XResolution$|YResolution$)")


def attribute(spec, *words):
    """The value of the one non-standard metadata attribute whose name holds
    all `words` (so the test does not fix the naming scheme)."""
    found = {a.name: a.value for a in spec.extra_attribs
             if not STANDARD_ATTRIBUTES.match(a.name) and all(w in a.name.lower() for w in words)}
    assert len(found) == 1, f"attributes with {words}: {found}"
    return next(iter(found.values()))


def numbers(text):
    return [float(x) for x in re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", str(text))]


def leftovers(directory):
    return sorted(p.name for p in Path(directory).iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """One scene rendered to EXR and PNG at W x H, shared by several tests."""
    directory = tmp_path_factory.mktemp("rendered")
    (directory / "scene.frac").write_text(SCENE)
    for name in ("out.exr", "out.png"):
        result = fractalc_cli("render", "scene.frac", "-o", name, "--width", W, "--height", H,
                              cwd=directory)
        assert result.returncode == 0, result.stderr
        assert "Traceback" not in result.stderr
    return directory


# ------------------------------------------------------------------ outputs

@pytest.mark.opencl
def test_png_is_8_bit_rgba_of_the_requested_size(rendered):
    pixels, names, spec = read_image(rendered / "out.png")
    assert (spec.width, spec.height, spec.nchannels) == (W, H, 4)
    assert names == ["R", "G", "B", "A"]
    assert spec.format == oiio.UINT8
    # the scene is there: not a flat image; the sphere in the middle is opaque
    assert pixels[..., :3].std() > 0.05
    assert pixels[H // 2, W // 2, 3] == 1.0


@pytest.mark.opencl
def test_png_is_the_srgb_encoding_of_the_exr(rendered):
    # through the default tone curve (tested against its formula in test_looks.py)
    from fractalc.write import tone_mapped
    png = read_image(rendered / "out.png")[0] * 255
    exr = exr_planes(rendered / "out.exr")
    linear = tone_mapped(np.stack([exr[c] for c in "RGB"], axis=-1))
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    assert np.abs(png[..., :3] - srgb * 255).max() <= 1.0


@pytest.mark.opencl
def test_exr_channels_and_planes(rendered):
    pixels, names, spec = read_image(rendered / "out.exr")
    assert (spec.width, spec.height) == (W, H)
    assert len(names) == 9 and set(names) == EXR_CHANNELS
    assert all(spec.channelformat(i) == oiio.FLOAT for i in range(spec.nchannels))
    planes = {name: pixels[..., i] for i, name in enumerate(names)}
    z = planes["Z"]
    hit = np.isfinite(z)
    assert 0.1 * hit.size < hit.sum() < 0.95 * hit.size
    assert np.all(z[~hit] == np.inf) and np.all(z[hit] > 0)
    normal = np.stack([planes[f"N.{c}"] for c in "xyz"], axis=-1)
    assert np.all(np.abs(np.linalg.norm(normal[hit], axis=-1) - 1) < 1e-3)
    assert np.all(planes["steps"] >= 1) and np.all(planes["steps"] <= 300)
    for c in "RGBA":
        assert np.isfinite(planes[c]).all()
    # the top of the box faces up (+z) where the rays hit it, near the bottom rows
    assert normal[hit][:, 2].max() > 0.99
    # misses show the background, linear
    background = np.stack([planes[c] for c in "RGB"], axis=-1)[~hit]
    np.testing.assert_allclose(background, np.broadcast_to([0.1, 0.1, 0.2], background.shape), atol=1e-6)


@pytest.mark.opencl
def test_exr_metadata_describes_the_render(rendered):
    _, _, spec = read_image(rendered / "out.exr")
    assert numbers(attribute(spec, "camera", "position")) == list(CAMERA["position"])
    assert numbers(attribute(spec, "camera", "target")) == list(CAMERA["target"])
    assert numbers(attribute(spec, "camera", "up")) == list(CAMERA["up"])
    assert numbers(attribute(spec, "camera", "fov")) == [CAMERA["fov"]]
    digest = hashlib.sha256((rendered / "scene.frac").read_bytes()).hexdigest()
    values = [str(a.value) for a in spec.extra_attribs]
    assert any(digest in v for v in values), "the scene file's sha256 is in the header"
    assert str(attribute(spec, "version")).endswith(fractalc.__version__)
    # the settings actually used: command line over file
    assert numbers(attribute(spec, "width")) == [W]
    assert numbers(attribute(spec, "height")) == [H]
    assert numbers(attribute(spec, "max_steps")) == [300]
    assert numbers(attribute(spec, "samples")) == [1]
    assert numbers(attribute(spec, "background")) == [0.1, 0.1, 0.2]


# ---------------------------------------------------------------------- --set

@pytest.mark.opencl
def test_set_changes_the_image(rendered):
    result = fractalc_cli("render", "scene.frac", "-o", "bigger.exr", "--width", W, "--height", H,
                          "--set", "r=1.4", "-q", cwd=rendered)
    assert result.returncode == 0, result.stderr
    default = exr_planes(rendered / "out.exr")
    bigger = exr_planes(rendered / "bigger.exr")
    assert np.isfinite(bigger["Z"]).sum() > np.isfinite(default["Z"]).sum()
    assert np.abs(bigger["R"] - default["R"]).max() > 0.1
    # the image centre looks at the sphere: a bigger sphere is nearer
    assert bigger["Z"][H // 2, W // 2] < default["Z"][H // 2, W // 2] - 0.2


@pytest.mark.parametrize("args, mentions", [
    (["--set", "radius=1"], "radius"),          # no such param
    (["--set", "r=3"], "r"),                    # outside [0.5, 1.5]
    (["--set", "r=abc"], "abc"),
    (["--set", "r"], "NAME=VALUE"),
    (["--width", "0"], "width"),
    (["--height", "-3"], "height"),
    (["--samples", "0"], "samples"),
], ids=["unknown param", "param out of range", "param not a number", "no value",
        "width 0", "negative height", "samples 0"])
def test_usage_errors_exit_2(tmp_path, args, mentions):
    (tmp_path / "scene.frac").write_text(SCENE)
    result = fractalc_cli("render", "scene.frac", "-o", "out.png", *args, cwd=tmp_path)
    assert_clean_failure(result, 2)
    assert mentions in result.stderr
    assert not (tmp_path / "out.png").exists()
    assert leftovers(tmp_path) == []


def test_param_errors_point_into_the_scene(tmp_path):
    (tmp_path / "scene.frac").write_text(SCENE)
    result = fractalc_cli("render", "scene.frac", "-o", "out.png", "--set", "r=3", cwd=tmp_path)
    assert_clean_failure(result, 2)
    line = SCENE.splitlines().index("param r = 1 in [0.5, 1.5]") + 1
    assert re.search(rf"^scene\.frac:{line}:\d+: error: ", result.stderr, re.M), result.stderr


# ------------------------------------------- failed renders leave no trace

BAD_SCENE = "scene sphere(radius: box())\n"


@pytest.mark.parametrize("case", ["scene error", "unknown param", "width 0", "bad device index",
                                  "bad device name", "bad device from the environment"])
def test_failed_render_keeps_the_existing_file(tmp_path, case):
    (tmp_path / "scene.frac").write_text(SCENE)
    (tmp_path / "bad.frac").write_text(BAD_SCENE)
    existing = os.urandom(64) + b"not really a png"
    (tmp_path / "out.png").write_bytes(existing)
    scene, extra, env, code = {
        "scene error": ("bad.frac", [], None, 2),
        "unknown param": ("scene.frac", ["--set", "nope=1"], None, 2),
        "width 0": ("scene.frac", ["--width", "0"], None, 2),
        "bad device index": ("scene.frac", ["--device", "99"], None, 1),
        "bad device name": ("scene.frac", ["--device", "no-such-device-anywhere"], None, 1),
        "bad device from the environment": ("scene.frac", [], {"FRACTALC_DEVICE": "no-such-device"}, 1),
    }[case]
    result = fractalc_cli("render", scene, "-o", "out.png", *extra, cwd=tmp_path, env=env)
    assert_clean_failure(result, code)
    if code == 1:
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    else:
        assert result.stderr.count("error:") >= 1
    assert (tmp_path / "out.png").read_bytes() == existing
    assert leftovers(tmp_path) == []


def test_scene_error_output_format(tmp_path):
    (tmp_path / "bad.frac").write_text(BAD_SCENE)
    result = fractalc_cli("render", "bad.frac", "-o", "out.exr", cwd=tmp_path)
    assert_clean_failure(result, 2)
    assert re.search(r"^bad\.frac:1:\d+: error: ", result.stderr, re.M)
    assert "^" in result.stderr
    assert not (tmp_path / "out.exr").exists()


@pytest.mark.parametrize("output", ["out.txt", "out", "out.frac"])
def test_unsupported_extension(tmp_path, output):
    (tmp_path / "scene.frac").write_text(SCENE)
    (tmp_path / "keep.txt").write_text("keep me")
    result = fractalc_cli("render", "scene.frac", "-o", output, cwd=tmp_path)
    assert_clean_failure(result, 2)
    assert not (tmp_path / output).exists()
    assert (tmp_path / "scene.frac").read_text() == SCENE
    assert (tmp_path / "keep.txt").read_text() == "keep me"
    assert leftovers(tmp_path) == []


def test_render_over_an_existing_extension_named_scene_is_refused(tmp_path):
    """`-o scene.frac` would clobber the scene; it is not an image extension."""
    (tmp_path / "scene.frac").write_text(SCENE)
    result = fractalc_cli("render", "scene.frac", "-o", "scene.frac", cwd=tmp_path)
    assert_clean_failure(result, 2)
    assert (tmp_path / "scene.frac").read_text() == SCENE


@pytest.mark.parametrize("output", ["missing/out.png", "dir.png"])
def test_unwritable_output_is_a_one_line_runtime_error(tmp_path, output):
    (tmp_path / "scene.frac").write_text(SCENE)
    (tmp_path / "dir.png").mkdir()
    result = fractalc_cli("render", "scene.frac", "-o", output, "--width", 8, "--height", 6,
                          cwd=tmp_path)
    assert_clean_failure(result, 1)
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert (tmp_path / "dir.png").is_dir() and list((tmp_path / "dir.png").iterdir()) == []
    assert leftovers(tmp_path) == []


@pytest.mark.opencl
def test_a_good_render_replaces_an_existing_file(tmp_path):
    (tmp_path / "scene.frac").write_text(SCENE)
    (tmp_path / "out.png").write_bytes(b"old")
    result = fractalc_cli("render", "scene.frac", "-o", "out.png", "--width", 8, "--height", 6,
                          "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert read_image(tmp_path / "out.png")[2].width == 8
    assert leftovers(tmp_path) == []


# ---------------------------------------------------------------- help, devices

@pytest.mark.parametrize("command, options", [
    ("render", ["-o", "--width", "--height", "--samples", "--set", "--precision", "--device"]),
    ("compile", ["-o", "--set", "--precision", "--device"]),
    ("check", []),
    ("devices", []),
])
def test_help(tmp_path, command, options):
    result = fractalc_cli(command, "--help", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"fractalc {command}" in result.stdout
    for option in options:
        assert option in result.stdout, option


def test_top_level_help_lists_the_commands(tmp_path):
    result = fractalc_cli("--help", cwd=tmp_path)
    assert result.returncode == 0
    for command in ("render", "compile", "check", "devices"):
        assert command in result.stdout


def test_the_product_names_its_sources_not_their_file_numbers(tmp_path):
    """Users have no "seed 000" (issue 21): the code, library, docs (images'
    metadata included), examples and help name the works themselves."""
    root = Path(__file__).resolve().parents[1]
    numbered = re.compile(rb"seed 0\d\d|seeds? documents?|^Seed:", re.I | re.M)
    files = [root / "README.md"] + [p for folder in ("fractalc", "docs", "stdlib_cl", "stdlib_frac", "examples")
                                    for p in (root / folder).rglob("*")
                                    if p.is_file() and "__pycache__" not in p.parts]
    assert [str(p.relative_to(root)) for p in files if numbered.search(p.read_bytes())] == []
    result = fractalc_cli("bench", "--help", cwd=tmp_path)
    assert "dissertation plan" in result.stdout and not numbered.search(result.stdout.encode())


@pytest.fixture(scope="module")
def device_lines(tmp_path_factory):
    result = fractalc_cli("devices", cwd=tmp_path_factory.mktemp("devices"))
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if re.match(r"[* ] \d+: ", line)]
    assert sum(line.startswith("*") for line in lines) == 1, "one device is marked the default"
    return [line[2:] for line in lines]


@pytest.mark.opencl
def test_devices_lists_at_least_one(device_lines):
    assert len(device_lines) >= 1
    assert device_lines[0].startswith("0")
    assert re.search(r"\b(CPU|GPU|other)\b", device_lines[0], re.I)
    assert all("builds: " in line and "speed rank " in line for line in device_lines)


def _render_with_device(directory, device):
    result = fractalc_cli("render", "scene.frac", "-o", f"device-{device}.exr", "--width", W,
                          "--height", H, "--device", device, "-q", cwd=directory)
    assert result.returncode == 0, result.stderr
    return exr_planes(directory / f"device-{device}.exr")


def _device_name(line):
    """The device's name as `fractalc devices` prints it: after 'N: ',
    before ' [KIND]'."""
    return re.match(r"\s*\d+\s*[:.)-]?\s*(.*?)\s*(\[|\(|;|$)", line).group(1)


@pytest.mark.opencl
def test_device_by_index_and_by_name(rendered, device_lines):
    default = exr_planes(rendered / "out.exr")
    by_index = _render_with_device(rendered, "0")
    word = re.findall(r"[A-Za-z]{3,}", _device_name(device_lines[0]))[0]
    by_name = _render_with_device(rendered, word.swapcase())      # case does not matter
    for planes in (by_index, by_name):
        assert set(planes) == EXR_CHANNELS
        hit = np.isfinite(planes["Z"])
        assert (hit != np.isfinite(default["Z"])).mean() < 0.02
        if len(device_lines) == 1:       # one device: the same image
            np.testing.assert_array_equal(planes["R"], default["R"])
            np.testing.assert_array_equal(planes["Z"], default["Z"])


@pytest.mark.opencl
def test_device_by_kind(rendered, device_lines):
    """`fractalc devices` prints each device's kind ([CPU], [GPU]); the README
    advertises `--device gpu`, so the kind selects a device too."""
    kind = re.search(r"\[(\w+)\]", device_lines[0]).group(1)
    planes = _render_with_device(rendered, kind.lower())
    assert set(planes) == EXR_CHANNELS


# ------------------------------------------------------------------- precision

@pytest.mark.opencl
def test_precision_double_is_nearly_float(rendered, device_lines):
    if "double: no" in device_lines[0]:
        pytest.skip("the device has no double precision")
    result = fractalc_cli("render", "scene.frac", "-o", "double.exr", "--width", W, "--height", H,
                          "--precision", "double", "-q", cwd=rendered)
    assert result.returncode == 0, result.stderr
    single = exr_planes(rendered / "out.exr")
    double = exr_planes(rendered / "double.exr")
    hit_single, hit_double = np.isfinite(single["Z"]), np.isfinite(double["Z"])
    assert (hit_single != hit_double).mean() < 0.01
    both = hit_single & hit_double
    assert np.allclose(double["Z"][both], single["Z"][both], rtol=1e-3, atol=1e-3)
    rgb = lambda p: np.stack([p[c] for c in "RGB"], axis=-1)  # noqa: E731
    close = np.abs(rgb(double) - rgb(single)).max(axis=-1) < 0.02
    assert close.mean() > 0.97
    # ... and it is a different computation
    assert not np.array_equal(double["Z"], single["Z"])


@pytest.mark.opencl
def test_precision_double_metadata(rendered, device_lines):
    if "double: no" in device_lines[0]:
        pytest.skip("the device has no double precision")
    path = rendered / "double-meta.exr"
    result = fractalc_cli("render", "scene.frac", "-o", path.name, "--width", 8, "--height", 6,
                          "--precision", "double", "-q", cwd=rendered)
    assert result.returncode == 0, result.stderr
    _, _, spec = read_image(path)
    precision = {a.name: str(a.value) for a in spec.extra_attribs if "precision" in a.name.lower()}
    assert precision, "the precision is recorded"
    assert set(precision.values()) == {"double"}, precision


# --------------------------------------------------------------------- compile

def test_compile_writes_standalone_source(tmp_path):
    (tmp_path / "scene.frac").write_text(SCENE)
    result = fractalc_cli("compile", "scene.frac", "-o", "scene.cl", "--lanes", 1, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    source = (tmp_path / "scene.cl").read_text()
    assert "#include" not in source
    assert "__kernel VECTOR_LANES_HINT void render(" in source
    assert "__kernel VECTOR_LANES_HINT void distance_at_points(" in source
    assert "#define LANES 1\n" in source
    assert source == fractalc.load(tmp_path / "scene.frac").kernel_source(lanes=1).replace(
        str(tmp_path / "scene.frac"), "scene.frac")


def test_compile_of_a_bad_scene_keeps_the_existing_file(tmp_path):
    (tmp_path / "bad.frac").write_text(BAD_SCENE)
    (tmp_path / "scene.cl").write_text("// old kernel\n")
    result = fractalc_cli("compile", "bad.frac", "-o", "scene.cl", cwd=tmp_path)
    assert_clean_failure(result, 2)
    assert (tmp_path / "scene.cl").read_text() == "// old kernel\n"
    assert leftovers(tmp_path) == []


# ------------------------------------------------ a write that fails midway

class _FailingOutput:
    """An ImageOutput that starts the file, then fails (a full disk) or is
    interrupted (Ctrl-C) while writing the pixels."""

    def __init__(self, failure):
        self.failure = failure

    def open(self, name, spec):
        with open(name, "wb") as f:
            f.write(b"partial")
        return True

    def write_image(self, pixels):
        if self.failure == "interrupt":
            raise KeyboardInterrupt
        return False

    def close(self):
        return True

    def geterror(self):
        return "No space left on device"


@pytest.mark.opencl
@pytest.mark.parametrize("failure", ["disk full", "interrupt"])
@pytest.mark.parametrize("name", ["out.exr", "out.png"])
def test_a_failed_write_keeps_the_existing_file(tmp_path, monkeypatch, failure, name):
    image = fractalc.loads(SCENE).render(width=8, height=6)
    path = tmp_path / name
    path.write_bytes(b"the previous image")

    class Factory:
        @staticmethod
        def create(filename, *args):
            return _FailingOutput(failure)

    monkeypatch.setattr(oiio, "ImageOutput", Factory)
    expected = KeyboardInterrupt if failure == "interrupt" else fractalc.RenderError
    with pytest.raises(expected):
        image.save(str(path))
    assert path.read_bytes() == b"the previous image"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
