"""Images a compositor can use (docs/compositing.md): coverage alpha, a
transparent background through EXR and PNG, OpenEXR's camera matrices, the
passes of `--aov`, half floats and 16-bit PNG. Renders are 64 x 48."""

import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

import fractalc
from fractalc import run
from fractalc.passes import DEFAULT_CHANNELS, PASSES

pytestmark = pytest.mark.opencl

W, H = 64, 48
CAMERA = "camera { position: (0.3, 0.5, 4), target: (0, 0, 0), fov: 40 }"
# a fixed hit threshold: the pixel-footprint one widens the silhouette by about a pixel
SPHERE = f"""
scene sphere(1)
{CAMERA}
light directional {{ direction: (-1, -1, -1) }}
render {{ width: {W}, height: {H}, epsilon: 1e-5, max_steps: 400, dither: 0 }}
"""
TRANSPARENT = SPHERE.replace("dither: 0", "dither: 0, background: transparent")
# a sphere over a ground, lit from above and the side: shadow, AO, specular
SHADED = f"""
material shiny {{ color: (0.8, 0.3, 0.2), specular: 0.6, shininess: 30 }}
scene sphere(1).material(shiny) | plane((0, 1, 0), offset: -1)
camera {{ position: (0, 0.6, 5), target: (0, 0.2, 0), fov: 45 }}
light directional {{ direction: (0.3, -1, -0.2), shadows: hard }}
render {{ width: {W}, height: {H}, glow: {{ strength: 0.5, radius: 0.2 }} }}
"""


def pixel_rays(camera, sub: int = 1) -> np.ndarray:
    """LANGUAGE.md's camera model: (H, W, sub * sub, 3) unit directions
    through a sub x sub grid of cell centres of each pixel."""
    block = np.array(run.camera_block(camera))
    forward, right, up, tan_half = block[3:6], block[6:9], block[9:12], block[12]
    offsets = (np.arange(sub) + 0.5) / sub
    i = (np.arange(W)[:, None] + offsets[None, :]).reshape(-1)
    j = (np.arange(H)[:, None] + offsets[None, :]).reshape(-1)
    x = (2 * i / W - 1) * (W / H) * tan_half
    y = (1 - 2 * j / H) * tan_half
    dirs = forward + x[None, :, None] * right + y[:, None, None] * up
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    # (H*sub, W*sub, 3) -> (H, W, sub*sub, 3)
    return dirs.reshape(H, sub, W, sub, 3).transpose(0, 2, 1, 3, 4).reshape(H, W, sub * sub, 3)


def read(path, unassociated=False):
    config = oiio.ImageSpec()
    if unassociated:
        config.attribute("oiio:UnassociatedAlpha", 1)
    file = oiio.ImageInput.open(str(path), config)
    spec = file.spec()
    pixels = np.asarray(file.read_image(oiio.UINT16 if str(spec.format) == "uint16" else oiio.FLOAT))
    file.close()
    return spec, {name: pixels[..., i] for i, name in enumerate(spec.channelnames)}


def test_coverage_alpha_is_the_analytic_coverage_of_the_sphere():
    scene = fractalc.loads(TRANSPARENT)
    alpha = scene.render(samples=16).rgba[..., 3]
    camera = scene.checked.camera
    origin = np.array(camera.position)
    dirs = pixel_rays(camera, sub=24)
    # a ray meets the unit sphere where its closest approach to the centre is within 1
    along = -(dirs @ origin)
    closest = np.linalg.norm(origin + along[..., None] * dirs, axis=-1)
    coverage = ((closest < 1) & (along > 0)).mean(axis=-1)
    edge = (coverage > 0) & (coverage < 1)
    assert edge.sum() > 40
    # 16 jittered samples estimate a pixel's coverage with an error of up to
    # about two of them where the edge crosses many cells: within 0.07 on
    # average, without bias, and no pixel far off (a centre-ray alpha errs by
    # about 0.25 on average, a silhouette a pixel too wide by about 0.5)
    error = (alpha - coverage)[edge]
    assert np.abs(error).mean() < 0.07 and abs(error.mean()) < 0.015
    assert np.abs(error).max() < 3 / 16 + 0.01
    assert np.all(alpha[coverage == 0] == 0) and np.all(alpha[coverage == 1] == 1)


def test_opaque_background_fills_the_misses_and_alpha_is_coverage():
    image = fractalc.loads(SPHERE).render()
    miss = ~np.isfinite(image.depth)
    assert np.all(image.rgba[..., 3][miss] == 0) and np.all(image.rgba[..., 3][~miss] == 1)
    np.testing.assert_allclose(image.rgba[..., :3][miss], np.broadcast_to([0.05, 0.05, 0.08], (miss.sum(), 3)),
                               rtol=1e-6)


def test_transparent_background_round_trips_through_exr_and_png(tmp_path):
    image = fractalc.loads(TRANSPARENT).render(samples=4)
    rgba = image.rgba
    miss = rgba[..., 3] == 0
    partial = (rgba[..., 3] > 0) & (rgba[..., 3] < 1)
    assert miss.sum() > 100 and partial.sum() > 10
    assert np.all(rgba[..., :3][miss] == 0), "misses are empty: zero colour"
    image.save(str(tmp_path / "t.exr"))
    image.save(str(tmp_path / "t.png"))
    _, exr = read(tmp_path / "t.exr")
    for i, c in enumerate("RGBA"):
        assert np.array_equal(exr[c], rgba[..., i]), c
    # PNG: straight alpha, the colour divided by the coverage, then sRGB
    _, png = read(tmp_path / "t.png", unassociated=True)
    png_rgba = np.stack([png[c] for c in "RGBA"], axis=-1)
    alpha = rgba[..., 3]
    assert np.abs(png_rgba[..., 3] - alpha).max() <= 0.5 / 255 + 1e-6
    covered = alpha > 0
    # (through the default tone curve, tested against its formula in test_looks.py)
    from fractalc.write import tone_mapped
    straight = tone_mapped(rgba[..., :3][covered] / alpha[covered][:, None])
    srgb = np.where(straight <= 0.0031308, 12.92 * straight, 1.055 * np.power(np.clip(straight, 0, 1), 1 / 2.4) - 0.055)
    assert np.abs(png_rgba[..., :3][covered] - np.clip(srgb, 0, 1)).max() <= 0.5 / 255 + 1e-6
    assert np.all(png_rgba[miss] == 0)


def test_world_to_ndc_projects_hit_points_onto_their_pixel_centres(tmp_path):
    image = fractalc.loads(SPHERE).render(aovs=["P"])
    image.save(str(tmp_path / "p.exr"))
    spec, planes = read(tmp_path / "p.exr")
    to_ndc = np.array(spec.getattribute("worldToNDC"), dtype=np.float64).reshape(4, 4)
    to_camera = np.array(spec.getattribute("worldToCamera"), dtype=np.float64).reshape(4, 4)
    hit = np.isfinite(planes["Z"])
    assert hit.sum() > 300
    points = np.stack([planes[f"P.{c}"][hit] for c in "xyz"] + [np.ones(hit.sum())], axis=-1)
    projected = points @ to_ndc        # row vectors, OpenEXR's convention
    ndc = projected[:, :2] / projected[:, 3:4]
    j, i = np.nonzero(hit)
    assert np.abs(ndc[:, 0] * W - (i + 0.5)).max() < 1e-3
    assert np.abs(ndc[:, 1] * H - (j + 0.5)).max() < 1e-3
    # camera space: z along the view is the depth along forward, positive in front
    in_camera = points @ to_camera
    forward = np.array(run.camera_block(fractalc.loads(SPHERE).checked.camera)[3:6])
    along = (points[:, :3] - [0.3, 0.5, 4]) @ forward
    np.testing.assert_allclose(in_camera[:, 2], along, atol=1e-5)
    assert np.all(in_camera[:, 2] > 0)


def test_png_carries_the_camera_matrices_and_metadata_as_text(tmp_path):
    scene = fractalc.loads(SPHERE)
    scene.render().save(str(tmp_path / "m.png"))
    spec, _ = read(tmp_path / "m.png")
    matrix = np.array(spec.getattribute("worldToNDC").split(), dtype=np.float64).reshape(4, 4)
    np.testing.assert_allclose(matrix, run.world_to_ndc(scene.checked.camera, W, H), rtol=1e-7)
    assert spec.getattribute("fractalc:scene_text") == SPHERE
    assert spec.getattribute("fractalc:render.samples") == "1"
    assert float(spec.getattribute("fractalc:render_seconds")) > 0


def test_every_pass_has_its_channels_and_plausible_values(tmp_path):
    scene = fractalc.loads(SHADED)
    image = scene.render(aovs=list(PASSES))
    image.save(str(tmp_path / "all.exr"))
    spec, planes = read(tmp_path / "all.exr")
    expected = set(DEFAULT_CHANNELS) | {c for names in PASSES.values() for c in names}
    assert set(spec.channelnames) == expected
    assert {str(f) for f in spec.channelformats} <= {"float"} and str(spec.format) == "float"
    hit = np.isfinite(planes["Z"])
    assert 0.3 < hit.mean() < 0.95
    # P is the camera plus Z along the pixel-centre ray
    dirs = pixel_rays(scene.checked.camera)[:, :, 0]
    p = np.stack([planes[f"P.{c}"] for c in "xyz"], axis=-1)
    expected_p = np.array(scene.checked.camera.position) + planes["Z"][..., None] * dirs
    assert np.abs(p[hit] - expected_p[hit]).max() < 1e-4
    assert np.all(p[~hit] == 0)
    # diffuse + specular is the shaded colour (no reflections or fog here; glow only on misses)
    rgb = np.stack([planes[c] for c in "RGB"], axis=-1)
    diffuse = np.stack([planes[f"diffuse.{c}"] for c in "RGB"], axis=-1)
    specular = np.stack([planes[f"specular.{c}"] for c in "RGB"], axis=-1)
    np.testing.assert_allclose((diffuse + specular)[hit], rgb[hit], atol=1e-5)
    assert specular[hit].max() > 0.05 and np.all(specular >= 0)
    # the ground under the sphere is in its shadow, and only shadow falls there
    shadow = planes["shadow"]
    assert set(np.unique(shadow)) <= {0.0, 1.0} and 0.02 < shadow[hit].mean() < 0.5
    ground = hit & (planes["N.y"] > 0.999)
    assert diffuse[ground & (shadow == 1)].max() < diffuse[ground & (shadow == 0)].min()
    # occlusion (at full strength: the scene has no AO): 1 on open ground,
    # darker in the crease where the sphere meets the ground
    ao = planes["ao"]
    assert np.all((ao >= 0) & (ao <= 1)) and np.all(ao[~hit] == 0)
    from_axis = np.linalg.norm(p[..., [0, 2]], axis=-1)
    assert np.all(ao[ground & (from_axis > 1.5)] > 0.99)
    crease = hit & (p[..., 1] < -0.8) & (from_axis < 1.2)
    assert (ao[crease] < 0.5).sum() >= 5
    # glow lights the misses only, and is what they add to the background
    glow = np.stack([planes[f"glow.{c}"] for c in "RGB"], axis=-1)
    assert np.all(glow[hit] == 0) and glow[~hit].max() > 0.01
    np.testing.assert_allclose(rgb[~hit], glow[~hit] + [0.05, 0.05, 0.08], atol=1e-6)


def test_the_material_pass_numbers_each_hit_by_its_material():
    scene = fractalc.loads("""material red { color: (1, 0, 0) }
material blue { color: (0, 0, 1) }
scene sphere(0.5).material(red) | sphere(0.5).translate((1.2, 0, 0)).material(blue)
    | sphere(0.4).translate((-1.2, 0, 0)).color((0, 1, 0)) | sphere(0.3).translate((0, 0, 1))
camera { position: (0, -4, 0), target: (0, 0, 0) }""")
    image = scene.render(width=48, height=24, aovs=("material",))
    material = image.passes["material"]
    hit = np.isfinite(image.depth)
    assert (material[~hit] == -1).all()
    # by column: the green sphere (left), red (middle), blue (right); the default one above the red
    middle_row = material[12]
    assert {int(v) for v in middle_row[middle_row >= 0]} == {1, 2, 3}
    assert 3 in middle_row[:16] and 1 in middle_row[16:32] and 2 in middle_row[32:]
    assert 0 in material[:8, 20:28]
    assert "FEATURE_PASS_MATERIAL" not in scene.kernel_source() and "CHANNEL_MATERIAL" not in scene.kernel_source()


def test_passes_not_asked_for_are_not_in_the_kernel():
    scene = fractalc.loads(SHADED)
    plain = scene.kernel_source()
    assert "shade_passes(p" not in plain and "CHANNEL_P_X" not in plain and "#define CHANNELS 9\n" in plain
    source = scene.kernel_source(aovs=["P", "shadow"])
    assert "shade_passes(p" in source and "#define CHANNEL_P_X 9\n" in source
    assert "CHANNEL_DIFFUSE_R" not in source and "#define CHANNELS 13\n" in source


def _fractalc(*args):
    return subprocess.run([sys.executable, "-m", "fractalc", *args], capture_output=True, text=True)


def test_cli_half_and_compression_and_16_bit_png(tmp_path):
    scene = tmp_path / "s.frac"
    scene.write_text(SPHERE)
    exr, png = tmp_path / "h.exr", tmp_path / "s.png"
    done = _fractalc("render", str(scene), "-o", str(exr), "--half", "--compression", "piz", "--aov", "P,ao", "-q")
    assert done.returncode == 0, done.stderr
    spec, planes = read(exr)
    formats = dict(zip(spec.channelnames, map(str, spec.channelformats)))
    assert {formats[c] for c in ("R", "G", "B", "A", "N.x", "steps", "ao")} == {"half"}
    assert {formats[c] for c in ("Z", "P.x", "P.y", "P.z")} == {"float"}
    assert spec.getattribute("compression") == "piz"
    assert np.isfinite(planes["Z"]).sum() > 300
    done = _fractalc("render", str(scene), "-o", str(png), "--bits", "16", "-q")
    assert done.returncode == 0, done.stderr
    spec, planes = read(png)
    assert str(spec.format) == "uint16"
    assert len(np.unique(planes["R"])) > 256     # more levels than 8 bits hold
    for bad in (["--half"], ["--compression", "zip"], ["--aov", "ao,P"]):
        done = _fractalc("render", str(scene), "-o", str(tmp_path / "x.png"), *bad)
        assert done.returncode == 2 and f"{bad[0]} is for EXR output" in done.stderr, done.stderr
        assert "Traceback" not in done.stderr
    # passes in PNG frames would be dropped as well
    done = _fractalc("animate", str(scene), "-o", str(tmp_path / "f%d.png"), "--aov", "ao")
    assert done.returncode == 2 and "--aov is for EXR frames" in done.stderr, done.stderr
    done = _fractalc("render", str(scene), "-o", str(tmp_path / "x.exr"), "--aov", "colour")
    assert done.returncode == 2 and "--aov" in done.stderr and "unknown pass 'colour'" in done.stderr
    assert not (tmp_path / "x.exr").exists() and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("value", ["transparent", (0.2, 0.3, 0.4)])
def test_background_accepts_transparent_or_a_colour(value):
    scene = fractalc.loads(SPHERE)
    image = scene.render(background=value, width=16, height=12)
    miss = ~np.isfinite(image.depth)
    expected = (0, 0, 0) if value == "transparent" else value
    np.testing.assert_allclose(image.rgba[..., :3][miss], np.broadcast_to(expected, (miss.sum(), 3)), rtol=1e-6)
    with pytest.raises(ValueError, match="background"):
        scene.render(background="clear")
