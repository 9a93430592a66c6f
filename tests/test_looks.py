"""Looks (docs/looks.md): exposure and the tone curve of PNG output (the
background of a scene is a known radiance, so the PNG's value of a missed
pixel is known exactly), spot lights in both integrators against their
formula, and cosine palettes driven by the orbit trap (read through the
albedo pass). Renders are 16 x 12 to 48 x 32."""

import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import fractalc

REPO = Path(__file__).resolve().parents[1]

SCENE = """
scene sphere(0.3)
camera { position: (0, -5, 0), target: (0, 0, 0), fov: 40 }
render { width: 16, height: 12, background: (0.2, 0.2, 0.2) }
"""


def srgb(x: float) -> float:
    return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055


def corner(path) -> np.ndarray:
    file = oiio.ImageInput.open(str(path))
    pixels = np.asarray(file.read_image(oiio.FLOAT))
    file.close()
    return pixels[0, 0, :3]


@pytest.mark.parametrize("keys, display", [
    ({}, 0.2),
    ({"exposure": 1}, 0.4),
    ({"exposure": -2}, 0.05),
    ({"exposure": 3, "tonemap": "none"}, 1.0),                        # 1.6: clipped
    ({"exposure": 3}, 0.8 + 0.2 * (1 - np.exp(-(1.6 - 0.8) / 0.2))),  # the default's shoulder
    ({"tonemap": "reinhard"}, 0.2 / 1.2),
    ({"tonemap": "reinhard", "exposure": 3}, 1.6 / 2.6),              # no longer clipped
    ({"tonemap": "aces"}, 0.2 * (2.51 * 0.2 + 0.03) / (0.2 * (2.43 * 0.2 + 0.59) + 0.14)),
])
@pytest.mark.opencl
def test_png_shows_the_radiance_times_two_to_the_exposure_through_the_curve(tmp_path, keys, display):
    scene = fractalc.loads(SCENE)
    image = scene.render(**keys)
    image.save(str(tmp_path / "a.png"))
    assert np.abs(corner(tmp_path / "a.png") - round(srgb(display) * 255) / 255).max() < 1e-6
    image.save(str(tmp_path / "a.exr"))
    assert np.all(corner(tmp_path / "a.exr") == np.float32(0.2)), "EXR stays the radiance as rendered"


def test_tone_curves_keep_order_and_roll_highlights_off():
    from fractalc.write import tone_mapped
    radiance = np.geomspace(1e-3, 1e3, 200)
    reinhard, aces = tone_mapped(radiance, 0.0, "reinhard"), tone_mapped(radiance, 0.0, "aces")
    soft = tone_mapped(radiance, 0.0, "soft")
    for shown in (reinhard, aces, soft):
        assert np.all(np.diff(shown) >= 0) and shown[0] > 0
    # the default: as rendered up to its knee, then a shoulder below white
    assert np.array_equal(soft[radiance <= 0.8], radiance[radiance <= 0.8])
    assert soft[radiance < 5].max() < 1.0 and np.all(np.diff(soft[(radiance > 0.8) & (radiance < 3)]) > 0)
    assert reinhard.max() < 1.0, "Reinhard never reaches white"
    # the ACES fit reaches white at 7.245 (0.08 x^2 - 0.56 x - 0.14 = 0)
    assert np.all(aces[radiance > 7.25] == 1.0) and np.all(aces[radiance < 7.24] < 1.0)


@pytest.mark.opencl
def test_floors_under_the_example_lights_keep_their_shading(tmp_path):
    # examples/primitives.frac: its floor (albedo 0.75) under a sun and a
    # blue point light, ambient 0.25: linear values up to 1.1. Clipped at
    # 1 (the old default) 17% of the floor's pixels were pure white in the
    # PNG; the default tone curve's shoulder keeps them below it.
    scene = fractalc.load(REPO / "examples" / "primitives.frac")
    image = scene.render(width=64, height=48, aovs=["P"])
    floor = np.isfinite(image.depth) & (image.normal[..., 2] > 0.99) & (image.passes["P"][..., 2] < 0.2)
    assert floor.sum() > 1000
    clipped = {}
    for curve in ("soft", "none"):
        image.metadata["render.tonemap"] = curve
        image.save(str(tmp_path / f"{curve}.png"))
        file = oiio.ImageInput.open(str(tmp_path / f"{curve}.png"))
        codes = np.asarray(file.read_image(oiio.UINT8))[..., :3]
        file.close()
        clipped[curve] = (codes[floor] == 255).any(axis=-1).mean()
    assert clipped["soft"] == 0 and clipped["none"] > 0.1, clipped


@pytest.mark.parametrize("entry, message", [
    ("tonemap: filmic", "'tonemap' must be 'soft' or 'none' or 'reinhard' or 'aces'"),
    ("exposure: 25", "'exposure' of 'render' must be between -20 and 20, not 25"),
])
def test_bad_tone_keys_are_errors_at_the_value(entry, message):
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads(f"scene sphere()\nrender {{ {entry} }}\n")
    assert message in str(caught.value)
    assert ":2:" in str(caught.value)


@pytest.mark.opencl
def test_exposure_and_tonemap_do_not_rebuild_the_kernel():
    scene = fractalc.loads(SCENE)
    scene.render()
    built = len(scene._programs)
    scene.render(exposure=2, tonemap="aces")
    assert len(scene._programs) == built


def test_every_example_in_the_looks_page_checks():
    import pathlib
    import re
    page = (pathlib.Path(__file__).parent.parent / "docs" / "looks.md").read_text()
    blocks = re.findall(r"```frac\n(.*?)```", page, re.S)
    assert blocks
    for block in blocks:
        fractalc.loads(block, path="docs/looks.md")


SPOT = """
material floor { color: (0.6, 0.6, 0.6), specular: 0 }
scene plane().material(floor)
camera { position: (0, -3, 3), target: (0, 0, 0), fov: 60 }
light spot { position: (0.2, 0, 2), direction: (0.3, 0, -1), angle: 20, falloff: 15, intensity: 4, color: (1, 0.8, 0.5) }
render { width: 48, height: 32, epsilon: 1e-5, dither: 0, INTEGRATOR
         environment: { zenith: (0, 0, 0), horizon: (0, 0, 0), ground: (0, 0, 0) } }
"""


def spot_light_at(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The spot's irradiance factor I cos / d^2 on the floor at points p,
    and how far into its cone each point is (the cosine to the axis)."""
    offset = np.array([0.2, 0, 2]) - p
    distance = np.linalg.norm(offset, axis=-1)
    axis = np.array([0.3, 0, -1]) / np.linalg.norm([0.3, 0, -1])
    along = -(offset / distance[..., None]) @ axis
    return 4 * (offset[..., 2] / distance) / distance ** 2, along


def smoothstep(edge0, edge1, x):
    t = np.clip((x - edge0) / (edge1 - edge0), 0, 1)
    return t * t * (3 - 2 * t)


@pytest.mark.opencl
@pytest.mark.parametrize("build", [{}, {"lanes": 1}, {"precision": "double"}])
def test_a_spot_light_lights_its_cone_and_fades_across_its_falloff(build):
    image = fractalc.loads(SPOT.replace("INTEGRATOR", ""), **build).render(aovs=["P"])
    strength, along = spot_light_at(image.passes["P"].astype(float))
    cone = smoothstep(math.cos(math.radians(35)), math.cos(math.radians(20)), along)
    assert (cone == 1).sum() > 50 and (cone == 0).sum() > 50 and ((cone > 0.1) & (cone < 0.9)).sum() > 20
    # the direct renderer: albedo times the light (the black environment is
    # the ambient light: none)
    for channel, colour in enumerate((1, 0.8, 0.5)):
        np.testing.assert_allclose(image.rgba[..., channel], 0.6 * colour * strength * cone,
                                   rtol=2e-4, atol=1e-6)


@pytest.mark.opencl
def test_the_path_tracer_lights_a_spot_s_cone_alike():
    image = fractalc.loads(SPOT.replace("INTEGRATOR", "integrator: path, bounces: 1,")).render(samples=4, aovs=["P"])
    strength, along = spot_light_at(image.passes["P"].astype(float))
    inside, outside = along > math.cos(math.radians(17)), along < math.cos(math.radians(38))
    np.testing.assert_allclose(image.rgba[..., 0][inside], 0.6 * strength[inside], rtol=0.03)
    assert np.all(image.rgba[..., :3][outside] == 0)


def test_a_spot_light_needs_a_position_and_a_direction():
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads("scene sphere()\nlight spot { position: (0, 0, 3), angle: 200 }\n")
    message = str(caught.value)
    assert "'angle' of 'light' must be less than 180, not 200" in message
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads("scene sphere()\nlight spot { position: (0, 0, 3) }\nlight area { }\n")
    message = str(caught.value)
    assert "a spot light needs 'direction'" in message
    assert "unknown light kind 'area' (known: directional, point, spot, sphere, rectangle)" in message


BULB = """
param shift = 0
scene mandelbulb(iterations: 8).color(COLORING) | sphere(0.3).translate((2, 0, 0)).color(COLORING)
camera { position: (0, -3.2, 0.6), target: (0.3, 0, 0), fov: 50 }
render { width: 48, height: 32, dither: 0 }
"""


def albedo_of(coloring: str, **build):
    """The albedo pass, and where the fractal is (not the ball)."""
    image = fractalc.loads(BULB.replace("COLORING", coloring), **build).render(aovs=["albedo", "P"])
    ball = np.linalg.norm(image.passes["P"] - [2, 0, 0], axis=-1) < 0.35
    return image.passes["albedo"].astype(float), np.isfinite(image.depth) & ~ball, ball


@pytest.mark.opencl
@pytest.mark.parametrize("build", [{}, {"precision": "double"}])
def test_a_cosine_palette_follows_the_orbit_trap(build):
    # orbit_trap from black to white shows t = trap * scale itself (below 1)
    t, fractal, _ = albedo_of("orbit_trap(near: (0, 0, 0), far: (1, 1, 1), trap: planes, scale: 2)", **build)
    a, b, c, d = (0.5, 0.4, 0.6), (0.5, 0.3, 0.4), (0.3, 0.5, 0.7), (0.5, 0.1, 0.8)
    palette = f"palette(a: {a}, b: {b}, c: {c}, d: {d}, trap: planes, scale: 2)"
    colour, _, _ = albedo_of(palette, **build)
    fractal &= t[..., 0] < 0.99
    assert fractal.sum() > 100 and np.ptp(t[fractal][:, 0]) > 0.3
    expected = np.add(a, np.multiply(b, np.cos(2 * np.pi * (np.multiply(c, t[fractal][:, :1]) + d))))
    np.testing.assert_allclose(colour[fractal], np.maximum(expected, 0), atol=2e-5)


@pytest.mark.opencl
def test_a_palette_on_a_plain_shape_is_its_colour_at_zero_and_follows_params():
    coloring = "palette(d: (shift, 0.33, 0.67))"
    albedo, _, ball = albedo_of(coloring)
    assert ball.sum() > 10
    start = 0.5 + 0.5 * np.cos(2 * np.pi * np.array([0, 0.33, 0.67]))
    np.testing.assert_allclose(albedo[ball], np.broadcast_to(start, (ball.sum(), 3)), atol=1e-6)
    scene = fractalc.loads(BULB.replace("COLORING", coloring), params={"shift": 0.5})
    scene.render(aovs=["albedo"])
    built = len(scene._programs)
    scene.set_params({"shift": 0.25})
    red = scene.render(aovs=["albedo"]).passes["albedo"][ball][:, 0]
    assert np.abs(red - 0.5).max() < 1e-6 and len(scene._programs) == built


@pytest.mark.opencl
def test_the_viewer_shows_the_exposure_and_tone_curve_as_a_png_would(tmp_path, monkeypatch):
    import io
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    pytest.importorskip("pygame")
    from fractalc.view import Viewer
    path = tmp_path / "scene.frac"
    path.write_text(SCENE.replace("background: (0.2, 0.2, 0.2)", "background: (0.2, 0.2, 0.2), exposure: 2, "
                                                                  "tonemap: reinhard"))
    viewer = Viewer(str(path), output_dir=str(tmp_path), out=io.StringIO(), err=io.StringIO())
    viewer.step(0.05)
    assert viewer.pixels()[0, 0, 0] == round(srgb(0.8 / 1.8) * 255)


@pytest.mark.opencl
def test_the_direct_renderer_shows_the_environment_where_rays_miss_and_in_mirrors():
    from fractalc import run
    sky = {"zenith": (0.2, 0.4, 1.0), "horizon": (0.9, 0.8, 0.7), "ground": (0.1, 0.3, 0.05)}
    scene = fractalc.loads(f"""
    material mirror {{ color: (1, 1, 1), reflectivity: 1 }}
    scene plane().material(mirror)
    camera {{ position: (0, -4, 1.5), target: (0, 0, 0.8), fov: 60 }}
    render {{ width: 32, height: 24, reflections: 1, dither: 0, epsilon: 1e-5,
              environment: {{ {", ".join(f"{k}: {v}" for k, v in sky.items())}, intensity: 2 }} }}
    """)
    image = scene.render()
    block = np.array(run.camera_block(scene.checked.camera))
    forward, right, up, tan_half = block[3:6], block[6:9], block[9:12], block[12]
    i, j = np.meshgrid(np.arange(32) + 0.5, np.arange(24) + 0.5)
    dirs = (forward + ((2 * i / 32 - 1) * 32 / 24 * tan_half)[..., None] * right
            + ((1 - 2 * j / 24) * tan_half)[..., None] * up)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    below = dirs[..., 2] < 0
    assert below.sum() > 100 and (~below).sum() > 100
    # the floor mirrors the sky: every pixel shows the sky in its direction turned upward
    z = np.abs(dirs[..., 2])[..., None]
    expected = 2 * (np.array(sky["horizon"]) + z * np.subtract(sky["zenith"], sky["horizon"]))
    # (where the floor is near: far off, float's normals of the plane wobble)
    near = ~below | (1.5 / np.abs(dirs[..., 2]) < 10)
    assert (below & near).sum() > 100
    np.testing.assert_allclose(image.rgba[..., :3][near], expected[near], atol=2e-4)


LIT_BY_SKY = """
material m {{ color: (0.7, 0.5, 0.3), specular: 0 }}
scene sphere(1).material(m)
camera {{ position: (0, -4, 1.5), target: (0, 0, 0), fov: 35 }}
render {{ width: 32, height: 24, dither: 0, epsilon: 1e-5, {keys} }}
"""
ALBEDO = np.array([0.7, 0.5, 0.3])


@pytest.mark.opencl
@pytest.mark.parametrize("build", [{}, {"lanes": 1, "precision": "double"}])   # (a GPU's lanes)
def test_a_uniform_environment_lights_a_diffuse_sphere_with_its_radiance(build):
    # irradiance pi L from every normal: the colour is albedo * L times the
    # AO (1 on a convex sphere), replacing the ambient 0.25 * albedo
    keys = "ao: 1, environment: { zenith: (1, 2, 4), horizon: (1, 2, 4), ground: (1, 2, 4), intensity: 0.5 }"
    image = fractalc.loads(LIT_BY_SKY.format(keys=keys), **build).render()
    covered = image.rgba[..., 3] == 1
    assert covered.sum() > 200
    np.testing.assert_allclose(image.rgba[..., :3][covered], np.broadcast_to(ALBEDO * [0.5, 1, 2],
                                                                            (covered.sum(), 3)), atol=1e-4)


def cosine_integral(normals, directions, solid_angle, radiance):
    """Irradiance over pi at each normal: the sum over quadrature directions
    of L(w) max(n.w, 0) dw / pi."""
    return np.maximum(normals @ directions.T, 0) @ (radiance * solid_angle[:, None]) / math.pi


@pytest.mark.opencl
def test_a_sky_gradient_lights_a_diffuse_sphere_as_quadrature_says():
    from test_pathtrace import sky_irradiance
    sky = {"zenith": (0.2, 0.4, 1.0), "horizon": (0.9, 0.8, 0.7), "ground": (0.1, 0.3, 0.05)}
    keys = f"environment: {{ {', '.join(f'{k}: {v}' for k, v in sky.items())} }}"
    image = fractalc.loads(LIT_BY_SKY.format(keys=keys)).render()
    covered = image.rgba[..., 3] == 1
    expected = ALBEDO / math.pi * sky_irradiance(image.normal[covered].astype(float), **sky)
    # nine spherical harmonics hold the irradiance to within a few percent
    # (Ramamoorthi and Hanrahan 2001; 2.1 % at worst for this sky, which has
    # a kink at the horizon), not exactly
    relative = image.rgba[..., :3][covered] / expected - 1
    assert covered.sum() > 200 and np.abs(relative).max() < 0.03 and np.abs(relative).mean() < 0.01


@pytest.mark.opencl
def test_an_environment_map_lights_a_diffuse_sphere_as_quadrature_over_its_texels_says(tmp_path):
    from test_pathtrace import write_map
    # a smooth sky with a broad bright patch, as a 128 x 64 image
    rows, columns = np.meshgrid(np.arange(64) + 0.5, np.arange(128) + 0.5, indexing="ij")
    colatitude, longitude = rows / 64 * math.pi, columns / 128 * 2 * math.pi - math.pi
    toward = np.stack([np.sin(colatitude) * np.cos(longitude), np.sin(colatitude) * np.sin(longitude),
                       np.cos(colatitude)], axis=-1)
    patch = np.maximum(toward @ np.array([0.6, -0.48, 0.64]), 0) ** 2
    pixels = np.array([0.3, 0.4, 0.6]) + 3 * patch[..., None] * np.array([1.0, 0.9, 0.7])
    write_map(tmp_path / "sky.exr", pixels)
    image = fractalc.loads(LIT_BY_SKY.format(keys="environment: { intensity: 1.5 }"))\
        .render(environment_map=str(tmp_path / "sky.exr"))
    covered = image.rgba[..., 3] == 1
    # the quadrature: the image's pixels, each over its own solid angle
    # (the kernel's 64 x 32 texels are their 2 x 2 means)
    solid_angle = (np.cos(colatitude - math.pi / 128) - np.cos(colatitude + math.pi / 128)) * 2 * math.pi / 128
    expected = ALBEDO * 1.5 * cosine_integral(image.normal[covered].astype(float), toward.reshape(-1, 3),
                                              solid_angle.reshape(-1), pixels.reshape(-1, 3))
    relative = image.rgba[..., :3][covered] / expected - 1
    assert covered.sum() > 200 and np.abs(relative).max() < 0.03 and np.abs(relative).mean() < 0.01, \
        (np.abs(relative).max(), np.abs(relative).mean())
    # the patch lights one side: the brightest pixel faces it
    brightest = image.normal[covered][np.argmax(image.rgba[..., 0][covered])]
    assert brightest @ np.array([0.6, -0.48, 0.64]) > 0.8


@pytest.mark.opencl
def test_an_mp4_made_from_exr_frames_shows_them_as_their_pngs(tmp_path):
    from fractalc.animate import _display_pixels
    image = fractalc.loads(SCENE).render(exposure=1.5, tonemap="aces")
    image.save(str(tmp_path / "frame.exr"))
    image.save(str(tmp_path / "frame.png"))
    from_exr, from_png = _display_pixels(str(tmp_path / "frame.exr")), _display_pixels(str(tmp_path / "frame.png"))
    assert np.abs(from_exr.astype(int) - from_png.astype(int)).max() <= 1
    assert from_exr[0, 0, 0] > round(srgb(0.2) * 255) + 30, "brighter than the radiance as rendered"


def _numpy_bulb_steps(points, iterations=8, bailout=2.0):
    """The steps the contract's power-8 Mandelbulb orbit takes before |z|
    passes the bailout (checked before each step), in float64."""
    z, steps = points.copy(), np.zeros(len(points))
    for _ in range(iterations):
        r = np.linalg.norm(z, axis=1)
        going = r <= bailout
        with np.errstate(all="ignore"):
            theta = np.where(r == 0, 0, np.arccos(np.clip(z[:, 2] / r, -1, 1))) * 8
        phi = np.arctan2(z[:, 1], z[:, 0]) * 8
        moved = (r ** 8)[:, None] * np.stack([np.sin(theta) * np.cos(phi), np.sin(phi) * np.sin(theta),
                                              np.cos(theta)], axis=1) + points
        z = np.where(going[:, None], moved, z)
        steps += going
    return steps


@pytest.mark.opencl
def test_colour_by_iteration_count_and_by_position():
    """trap: iterations counts the orbit's steps (the same loop), radius and
    height read the point: black-to-white ramps show t itself."""
    ramp = "orbit_trap(near: (0, 0, 0), far: (1, 1, 1), trap: {kind}, scale: {scale})"
    image = fractalc.loads(BULB.replace("COLORING", ramp.format(kind="iterations", scale=0.125))).render(
        aovs=["albedo", "P"])
    fractal = np.isfinite(image.depth) & (np.linalg.norm(image.passes["P"], axis=-1) < 1.3)   # not the ball
    counted = image.passes["albedo"][fractal][:, 0] * 8
    expected = _numpy_bulb_steps(image.passes["P"][fractal].astype(float))
    assert fractal.sum() > 100 and len(np.unique(np.round(counted))) > 1
    assert np.mean(np.abs(counted - expected) < 1e-3) > 0.95      # hit points on a boundary may count one more
    for kind, of_point in (("radius", lambda p: np.linalg.norm(p, axis=1)), ("height", lambda p: p[:, 2])):
        image = fractalc.loads(BULB.replace("COLORING", ramp.format(kind=kind, scale=0.5))).render(
            aovs=["albedo", "P"])
        t = np.clip(0.5 * of_point(image.passes["P"][fractal].astype(float)), 0, 1)
        np.testing.assert_allclose(image.passes["albedo"][fractal][:, 0], t, atol=2e-3)


def scene_with_map(tmp_path, entry: str):
    """scenes/scene.frac under tmp_path, its render block's environment
    holding `entry`; a map of radiance (0.2, 0.4, 0.8) in scenes/maps."""
    from test_pathtrace import write_map
    (tmp_path / "scenes" / "maps").mkdir(parents=True)
    write_map(tmp_path / "scenes" / "maps" / "sky.exr", np.ones((8, 16, 3)) * [0.2, 0.4, 0.8])
    path = tmp_path / "scenes" / "scene.frac"
    path.write_text("scene sphere(1)\ncamera { position: (0, -4, 0), target: (0, 0, 0) }\n"
                    f"render {{ width: 16, height: 12, environment: {{ {entry} }} }}\n")
    return path


@pytest.mark.opencl
def test_a_scene_file_names_its_environment_map_relative_to_its_folder(tmp_path, monkeypatch):
    from test_pathtrace import write_map
    path = scene_with_map(tmp_path, 'map: "maps/sky.exr", intensity: 2')
    monkeypatch.chdir(tmp_path)           # not the scene's folder
    scene = fractalc.load(path)
    image = scene.render()
    missed = image.rgba[..., 3] == 0
    assert missed.sum() > 50
    np.testing.assert_allclose(image.rgba[..., :3][missed], np.broadcast_to([0.4, 0.8, 1.6], (missed.sum(), 3)),
                               rtol=1e-6)
    # the sphere (albedo 0.8) lit by the map: the environment light
    hit = image.rgba[..., 3] == 1
    np.testing.assert_allclose(image.rgba[..., :3][hit], np.broadcast_to([0.32, 0.64, 1.28], (hit.sum(), 3)),
                               atol=1e-4)
    # the map is read on the host: its name is nowhere in the kernel
    source = scene.kernel_source()
    assert "sky.exr" not in source and str(tmp_path / "scenes" / "maps") not in source
    assert "ENVIRONMENT_TEXELS" in source
    # the API's (and the command line's) map replaces the file's
    write_map(tmp_path / "other.exr", np.ones((8, 16, 3)) * [1.0, 0.5, 0.25])
    other = scene.render(environment_map=tmp_path / "other.exr")
    np.testing.assert_allclose(other.rgba[..., :3][missed], np.broadcast_to([2, 1, 0.5], (missed.sum(), 3)),
                               rtol=1e-6)
    with pytest.raises(ValueError, match="from Python give environment_map=FILE"):
        scene.render(environment={"map": "maps/sky.exr"})


@pytest.mark.parametrize("entry, offset, message", [     # offset: of the error in the entry
    ('map: "missing.exr"', 5, "cannot read the environment map"),
    ('map: "scene.frac"', 5, "cannot read the environment map"),              # not an image
    ('map: "maps/s\x01ky.exr"', 12, "a control character (code 1) in a string"),
    ('map: "maps/sky.exr', 5, "unterminated string: a string ends with '\"' on the line it starts"),
    ('map: 3', 5, "'map' takes a file name in quotes"),
    ('map: ""', 5, "an empty file name"),
    ('zenith: "maps/sky.exr"', 8, "'zenith' takes a value, not a string"),
])
def test_bad_map_names_are_errors_at_their_place(tmp_path, capsys, entry, offset, message):
    from fractalc.cli import main
    path = scene_with_map(tmp_path, entry)
    column = path.read_text().splitlines()[2].index(entry) + 1 + offset
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.load(path)
    assert (caught.value.line, caught.value.column) == (3, column) and message in str(caught.value)
    # the command line: the same error, with its line and caret, exit code 2
    assert main(["render", str(path), "-o", str(tmp_path / "out.png"), "-q"]) == 2
    error = capsys.readouterr().err
    assert f"{path}:3:{column}: error: " in error and "^" in error and "Traceback" not in error
    assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("text", [
    'render { environment: { map: "sky.exr", intensity: 2 } }\nscene sphere()',
    'render {\n  environment: {\n    map: "a b/#c.hdr"\n  }\n}\nscene sphere()',
    'camera { fov: "" }',
])
def test_both_parsers_read_strings_alike(text):
    from fractalc import parse as parse_module
    from test_large_input import as_data, lark_decls
    assert as_data(parse_module._FastParser(text).program()) == as_data(lark_decls(text))


def test_a_string_is_only_a_block_entrys_value():
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads('scene sphere("sky.exr")')
    assert (caught.value.line, caught.value.column) == (1, 14)
    assert "a string is a file name, only ever a block entry's value" in str(caught.value)
