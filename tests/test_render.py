"""Rendering: depth, normals and hit/miss of the compiled kernel against
analytic ray intersections (LANGUAGE.md's camera model, computed in numpy),
the sanity of every output plane, anti-aliasing, 1 vs 8 lanes, param changes
without rebuilding, what the emitted source contains, and the standalone
kernel of `fractalc compile` run with bare pyopencl."""

import os
import re
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc import build as build_module
from fractalc import run as run_module
from fractalc.devices import default_device, list_devices, open_device
from fractalc.emit import Target, emit
from fractalc.lower import lower

import reference as ref

REPO = Path(__file__).resolve().parents[1]
W, H = 64, 48
EPSILON = 1e-4          # the hit threshold of the analytic comparisons
# Float rounding of ray distances of a few units, on top of the threshold.
ABSOLUTE = 2e-5


# ---------------------------------------------------------------- the camera

def camera_frame(position, target, up, fov):
    """LANGUAGE.md: forward, right, up' and tan(fov/2)."""
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    right /= np.linalg.norm(right)
    up_ = np.cross(right, forward)
    return position, forward, right, up_, np.tan(np.radians(fov) / 2)


def primary_rays(camera, width=W, height=H):
    """Origin (3,) and unit directions (H, W, 3) through the pixel centres."""
    position, forward, right, up_, tan_half = camera_frame(**camera)
    i = np.arange(width) + 0.5
    j = np.arange(height) + 0.5
    x = (2 * i / width - 1) * (width / height) * tan_half
    y = (1 - 2 * j / height) * tan_half
    dirs = forward + x[None, :, None] * right + y[:, None, None] * up_
    return position, dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)


def camera_text(camera):
    vec = lambda v: "(" + ", ".join(repr(float(c)) for c in v) + ")"  # noqa: E731
    return (f"camera {{ position: {vec(camera['position'])}, target: {vec(camera['target'])}, "
            f"up: {vec(camera['up'])}, fov: {camera['fov']} }}")


def ray_sphere(origin, dirs, centre, radius):
    """Ray distance to the sphere (+inf on a miss, 0 from inside) and the
    outward normal at the hit."""
    oc = origin - np.asarray(centre, dtype=np.float64)
    b = dirs @ oc
    c = oc @ oc - radius * radius
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0))
    t = -b - root
    t = np.where(c <= 0, 0.0, t)
    t = np.where((disc < 0) | ((c > 0) & (t < 0)), np.inf, t)
    p = origin + dirs * np.where(np.isfinite(t), t, 0)[..., None]
    return t, (p - centre) / radius


def ray_box(origin, dirs, centre, size):
    """Ray distance to an axis-aligned box (slab method) and the outward
    normal of the face entered."""
    half = np.asarray(size, dtype=np.float64) / 2
    o = origin - np.asarray(centre, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        t1 = (-half - o) * inv
        t2 = (half - o) * inv
    near = np.minimum(t1, t2)
    far = np.maximum(t1, t2)
    t_near = near.max(axis=-1)
    t_far = far.min(axis=-1)
    hit = (t_near <= t_far) & (t_far >= 0)
    t = np.where(hit, np.maximum(t_near, 0), np.inf)
    axis = near.argmax(axis=-1)
    normal = np.zeros(dirs.shape)
    np.put_along_axis(normal, axis[..., None], -np.sign(np.take_along_axis(dirs, axis[..., None], -1)), -1)
    return t, normal


def silhouette_band(hit):
    """Pixels whose 3x3 neighbourhood holds both hits and misses."""
    padded = np.pad(hit, 1, mode="edge")
    stack = np.stack([padded[1 + dy:1 + dy + hit.shape[0], 1 + dx:1 + dx + hit.shape[1]]
                      for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    return stack.any(axis=0) & ~stack.all(axis=0)


def render_scene(shape, camera, extra="", **keys):
    text = (f"scene {shape}\n{camera_text(camera)}\n"
            f"render {{ width: {W}, height: {H}, epsilon: {EPSILON}, max_steps: 1000 }}\n{extra}")
    return fractalc.loads(text).render(**keys)


def check_against_analytic(image, t_true, n_true, origin, dirs, check_normals=True):
    hit_true = np.isfinite(t_true)
    hit = np.isfinite(image.depth)
    band = silhouette_band(hit_true)
    # the scene is in view, but does not fill it
    assert 0.05 * hit.size < hit_true.sum() < 0.9 * hit.size
    wrong = (hit != hit_true) & ~band
    assert not wrong.any(), f"hit/miss differ away from the silhouette at {np.argwhere(wrong)[:5]}"
    assert (hit != hit_true).sum() <= band.sum()
    # depth on common hits: sphere tracing stops within EPSILON of the
    # surface, i.e. at most EPSILON / cos(incidence) short of the true hit
    common = hit & hit_true & ~band
    assert common.sum() > 0.5 * hit_true.sum()
    cos = np.abs(np.sum(dirs * n_true, axis=-1))
    short = t_true[common] - image.depth[common]
    allowed = (EPSILON / np.maximum(cos, 0.05) + ABSOLUTE)[common]
    assert short.min() >= -ABSOLUTE, f"overshoot of {-short.min():g}"
    assert (short <= allowed).all(), f"depth error up to {short.max():g}"
    if check_normals:
        error = np.linalg.norm(image.normal - n_true, axis=-1)[common]
        assert error.max() < 1e-2, f"normal error up to {error.max():g}"
    # misses: depth +inf, normal 0
    miss = ~hit
    assert np.all(image.depth[miss] == np.inf)


SPHERE_CAMERAS = {
    "centred": dict(position=(0, -4, 0), target=(0, 0, 0), up=(0, 0, 1), fov=40),
    "oblique": dict(position=(3, -2.5, 1.5), target=(0.2, 0.1, -0.3), up=(0, 0, 1), fov=50),
    "tilted up": dict(position=(-1, 2, 3.5), target=(0, 0, 0), up=(1, 1, 0), fov=35),
}


@pytest.mark.opencl
@pytest.mark.parametrize("name", SPHERE_CAMERAS)
def test_sphere_depth_and_normals(name):
    camera = SPHERE_CAMERAS[name]
    image = render_scene("sphere(1)", camera)
    origin, dirs = primary_rays(camera)
    t, n = ray_sphere(origin, dirs, (0, 0, 0), 1.0)
    check_against_analytic(image, t, n, origin, dirs)


@pytest.mark.opencl
@pytest.mark.parametrize("name", ["centred", "oblique"])
def test_forward_normals_reuse_the_marchs_last_estimate(name):
    """`normals: forward` differences three evaluations against the one the
    march took at the hit: the normals are as exact as the tetrahedron's
    (an estimate other than the hit's, such as 0, would tilt them by up to
    a threshold over the step, the same size)."""
    camera = SPHERE_CAMERAS[name]
    image = render_scene("sphere(1)", camera, normals="forward")
    origin, dirs = primary_rays(camera)
    t, n = ray_sphere(origin, dirs, (0, 0, 0), 1.0)
    check_against_analytic(image, t, n, origin, dirs)


@pytest.mark.opencl
def test_sphere_off_centre():
    """A translated sphere away from the image centre (the camera looks at the origin)."""
    camera = SPHERE_CAMERAS["oblique"]
    centre, radius = (0.7, 0.3, 0.9), 0.6
    image = render_scene(f"sphere({radius}).translate({centre})", camera)
    origin, dirs = primary_rays(camera)
    t, n = ray_sphere(origin, dirs, centre, radius)
    # the sphere is off-centre in the image: its pixels' mean lies away from the middle
    rows, cols = np.nonzero(np.isfinite(t))
    assert abs(cols.mean() - W / 2) > 4 or abs(rows.mean() - H / 2) > 4
    check_against_analytic(image, t, n, origin, dirs)


@pytest.mark.parametrize("camera", [
    dict(position=(2.5, -3, 2), target=(0, 0, 0), up=(0, 0, 1), fov=45),
    dict(position=(-3, -1, -1.5), target=(0.2, 0, 0.1), up=(0, 0, 1), fov=45),
], ids=["above", "below"])
@pytest.mark.opencl
def test_box_depth_and_normals(camera):
    centre, size = (0.2, 0.1, -0.1), (1.2, 1.6, 0.8)
    image = render_scene(f"box({size}).translate({centre})", camera)
    origin, dirs = primary_rays(camera)
    t, n = ray_box(origin, dirs, centre, size)
    check_against_analytic(image, t, n, origin, dirs)


def test_depth_analytic_helpers_agree_with_reference_distances():
    """The analytic intersections used above are the zeros of reference.py's
    distances (a check of the test's own geometry)."""
    camera = SPHERE_CAMERAS["oblique"]
    origin, dirs = primary_rays(camera)
    for t, d in [(ray_sphere(origin, dirs, (0.7, 0.3, 0.9), 0.6)[0],
                  lambda p: ref.sphere(p - np.array([0.7, 0.3, 0.9]), 0.6)),
                 (ray_box(origin, dirs, (0.2, 0.1, -0.1), (1.2, 1.6, 0.8))[0],
                  lambda p: ref.box(p - np.array([0.2, 0.1, -0.1]), (1.2, 1.6, 0.8)))]:
        hits = np.isfinite(t)
        p = origin + dirs[hits] * t[hits][:, None]
        assert np.abs(d(p)).max() < 1e-9


# ------------------------------------------------------- every output plane

SANE_SCENES = {
    "sphere": "scene sphere()",
    "csg and lights": textwrap.dedent("""\
        material red { color: (0.9, 0.1, 0.1), specular: 0.8, shininess: 64 }
        let body = subtract(box(1.6).round(0.1), sphere(0.9), smooth: 0.1).material(red)
        scene union(body, torus(1.3, 0.2).twist(0.5), plane(offset: -0.8), smooth: 0.2)
        camera { position: (3, -4, 2.5), target: (0, 0, 0), fov: 45 }
        light directional { direction: (-0.4, 0.7, -1), shadows: soft, softness: 10 }
        light point { position: (2, -2, 3), color: (0.4, 0.6, 1.0), intensity: 8, shadows: hard }
        render { ao: 0.7, background: (0.2, 0.3, 0.4) }
        """),
    "repetition to the horizon": textwrap.dedent("""\
        scene sphere(0.3).repeat((1, 1, 0)) | plane(offset: -0.5)
        camera { position: (0.5, 0.5, 0.6), target: (5, 3, 0), fov: 70 }
        light directional { direction: (1, 1, -1), shadows: soft }
        render { max_distance: 30, max_steps: 64, ao: 1 }
        """),
    "looking away": textwrap.dedent("""\
        scene sphere()
        camera { position: (0, -4, 0), target: (0, -8, 0) }
        """),
}


def check_planes_sane(image, max_steps):
    for name, plane in [("rgba", image.rgba), ("normal", image.normal), ("steps", image.steps)]:
        assert np.isfinite(plane).all(), f"{name} has NaN or Inf"
    assert not np.isnan(image.depth).any()
    hit = np.isfinite(image.depth)
    assert np.all(np.isinf(image.depth[~hit]) & (image.depth[~hit] > 0)), "only +inf for misses"
    assert np.all(image.depth[hit] >= 0)
    assert image.rgba.shape == (H, W, 4) and image.depth.shape == (H, W)
    assert image.normal.shape == (H, W, 3) and image.steps.shape == (H, W)
    assert image.rgba.min() >= 0 and image.rgba[..., :3].max() < 20
    alpha = image.rgba[..., 3]
    assert np.all((alpha >= 0) & (alpha <= 1)) and np.all(alpha[hit] == 1)
    # a hit takes at least one step; a ray that misses the scene's bounding
    # sphere takes none
    assert image.steps[hit].min(initial=1) >= 1 and image.steps.min() >= 0
    assert image.steps.max() <= max_steps
    assert np.all(image.steps == np.round(image.steps))
    lengths = np.linalg.norm(image.normal[hit], axis=-1)
    assert np.all(np.abs(lengths - 1) < 1e-3), "hit normals are unit vectors"
    assert np.all(image.normal[~hit] == 0)
    return hit


@pytest.mark.opencl
@pytest.mark.parametrize("name", SANE_SCENES)
def test_output_planes_are_sane(name):
    scene = fractalc.loads(SANE_SCENES[name])
    image = scene.render(width=W, height=H)
    hit = check_planes_sane(image, scene.checked.render.max_steps)
    if name == "looking away":
        assert not hit.any()
        background = np.array(scene.checked.render.background, dtype=np.float32)
        assert np.allclose(image.rgba[..., :3], background)
    else:
        assert hit.any()


@pytest.mark.parametrize("shape, position", [
    ("box(10)", (0.5, -1, 0.3)),
    ("plane(offset: 1)", (0, 0, 0)),                       # below the plane: inside
    ("sphere(1).translate((0, 0, 0.2)) | box(0.1).translate((3, 0, 0))", (0, 0, 0)),
])
@pytest.mark.opencl
def test_camera_inside_a_solid_hits_at_zero(shape, position):
    text = (f"scene {shape}\ncamera {{ position: {position}, target: (1, 2, 0.5) }}\n"
            "light directional { direction: (0, 0, -1), shadows: soft }\nrender { ao: 0.5 }")
    scene = fractalc.loads(text)
    assert scene.distance(np.array([position], dtype=float))[0] <= 0
    image = scene.render(width=W, height=H)
    assert np.isfinite(image.rgba).all() and np.isfinite(image.normal).all()
    assert np.all(image.depth == 0)
    # one evaluation at t = 0, and with CPU lanes first the packet's cone's
    # there (a march step of each of its rays)
    assert np.all(image.steps == (2 if scene.lanes_in_use > 1 else 1))
    assert image.rgba.min() >= 0 and image.rgba.max() < 20


# ------------------------------------------------------------ anti-aliasing

AA_SCENE = textwrap.dedent("""\
    scene box((1.2, 0.2, 0.9)).rotate((0, 1, 0), 20)
    camera { position: (0, -4, 0), target: (0, 0, 0), fov: 35 }
    render { width: 64, height: 48, epsilon: 1e-4 }
    """)


@pytest.mark.opencl
def test_samples_antialias_only_silhouettes():
    scene = fractalc.loads(AA_SCENE)
    one = scene.render(samples=1)
    four = scene.render(samples=4)
    again = scene.render(samples=4)
    other_seed = scene.render(samples=4, seed=7)
    # AOVs come from the pixel-centre ray
    np.testing.assert_array_equal(four.depth, one.depth)
    np.testing.assert_array_equal(four.normal, one.normal)
    np.testing.assert_array_equal(four.steps, one.steps)
    # deterministic for a seed
    np.testing.assert_array_equal(again.rgba, four.rgba)
    # colour changes at the silhouette, (almost) nowhere else
    band = silhouette_band(np.isfinite(one.depth))
    difference = np.abs(four.rgba[..., :3] - one.rgba[..., :3]).max(axis=-1)
    assert difference[~band].max() < 0.02, "anti-aliasing changed pixels away from edges"
    assert difference[band].max() > 0.2
    assert (difference[band] > 0.05).sum() >= 10
    # AA colours at the edge lie between the surface and the background
    lo = np.minimum(one.rgba[..., :3].min(axis=(0, 1)), four.rgba[..., :3].min(axis=(0, 1)))
    assert np.all(four.rgba[..., :3] >= lo - 1e-6)
    assert np.all(four.rgba[..., :3] <= one.rgba[..., :3].max(axis=(0, 1)) + 1e-3)
    # another seed jitters differently, at the edges only
    seed_difference = np.abs(other_seed.rgba - four.rgba).max(axis=-1)
    assert seed_difference.max() > 0
    assert seed_difference[~band].max() < 0.02


# -------------------------------------------------------------------- lanes

LANES_SCENE = textwrap.dedent("""\
    param k = 0.3 in [0, 1]
    material gold { color: (1.0, 0.78, 0.34), specular: 0.6, shininess: 32 }
    let body = union(box(1.2).round(0.1).twist(0.4), sphere(0.8).translate((0.6, 0, 0.6)), smooth: k)
    scene body.material(gold) | torus(1.5, 0.15).repeat((0, 0, 2)) | plane(offset: -1)
    camera { position: (3.5, -4, 2), target: (0, 0, 0), fov: 45 }
    light directional { direction: (-0.5, 0.4, -1), shadows: soft, softness: 12 }
    light point { position: (2, -2, 3), intensity: 6 }
    render { ao: 0.6, cone_marching: off }
    """)
# (without the cone, each ray's march is the same at any lanes; a packet's
# cone depends on the packet: its images are tested in tests/hard)


def _built(scene, lanes):
    device = open_device(None)
    source = emit(lower(scene.checked), Target(lanes=lanes, exact_native=device.lane_choice.native_exact))
    assert f"#define LANES {lanes}\n" in source
    return build_module.build(source, device), device


@pytest.mark.opencl
@pytest.mark.parametrize("lanes", [1, 4, 16])
def test_lanes_agree_with_eight(lanes):
    scene = fractalc.loads(LANES_SCENE)
    params = [scene.params["k"]]
    # an odd width: the last work-item's lanes run off the image
    width, height = 61, 37
    frame = run_module.Frame(width, height, 1, 0, run_module.camera_block(scene.checked.camera))
    planes = {}
    for n in (8, lanes):
        program, device = _built(scene, n)
        pixels = run_module.RenderKernel(program, device, n, False).render(frame, params)
        assert pixels.shape == (height, width, len(run_module.CHANNELS))
        planes[n] = dict(zip(run_module.CHANNELS, np.moveaxis(pixels, -1, 0)))
    a, b = planes[8], planes[lanes]
    hits = np.isfinite(a["Z"]) & np.isfinite(b["Z"])
    assert (np.isfinite(a["Z"]) != np.isfinite(b["Z"])).sum() <= 2
    assert hits.sum() > 0.5 * width * height
    assert np.abs(a["Z"][hits] - b["Z"][hits]).max() < 1e-4
    for name in ("R", "G", "B", "N.x", "N.y", "N.z"):
        close = np.abs(a[name] - b[name]) < 1e-3
        assert close.mean() > 0.99, f"{name} differs on {(~close).sum()} pixels"
    points = np.random.default_rng(5).uniform(-3, 3, (1001, 3))
    d = {n: run_module.distances(_built(scene, n)[0], open_device(None), points, params, n, False)
         for n in (8, lanes)}
    np.testing.assert_allclose(d[lanes], d[8], rtol=1e-5, atol=1e-5)


@pytest.mark.opencl
def test_tiles_join_seamlessly(monkeypatch):
    """Small tiles (several per row and column, ragged at the edges) give the
    same image as one tile."""
    scene = fractalc.loads(LANES_SCENE)
    whole = scene.render(width=61, height=37)
    monkeypatch.setattr(run_module, "TILE_WIDTH", 16)
    monkeypatch.setattr(run_module, "TILE_HEIGHT", 10)
    monkeypatch.setattr(run_module, "CPU_TILE_HEIGHT", 10)
    tiled = scene.render(width=61, height=37)
    for plane in ("rgba", "depth", "normal", "steps"):
        np.testing.assert_array_equal(getattr(tiled, plane), getattr(whole, plane))


# ---------------------------------------------------------- params, caching

PARAM_SCENE = textwrap.dedent("""\
    param r = 1 in [0.5, 1.5]
    param shift = 0 in [-1, 1]
    scene sphere(r).translate((shift, 0, 0)) | box(0.5).translate((0, 0, -1.2 * r))
    camera { position: (0, -4, 1), target: (0, 0, 0), fov: 40 }
    # unique: UNIQUE
    """)


def _unique_scene():
    """A scene text no other test built (its constant differs)."""
    return PARAM_SCENE.replace("box(0.5)", f"box({0.5 + int(uuid.uuid4().hex[:6], 16) * 1e-9:.9f})")


@pytest.mark.opencl
def test_params_change_the_image_without_rebuilding():
    text = _unique_scene()
    before = build_module.statistics.builds
    scene = fractalc.loads(text)
    first = scene.render(width=W, height=H)
    assert build_module.statistics.builds == before + 1, "a new scene builds once"
    assert np.allclose(scene.distance([[0.5, 0, 0]]), -0.5, atol=1e-5)
    assert build_module.statistics.builds == before + 2, "and its estimate alone once (emit_distance)"
    builds = build_module.statistics.builds

    scene.set_params({"r": 1.3})
    bigger = scene.render(width=W, height=H)
    assert np.isfinite(bigger.depth).sum() > np.isfinite(first.depth).sum()
    scene.set_params({"shift": 0.5})
    moved = scene.render(width=W, height=H)
    assert not np.array_equal(moved.depth, bigger.depth)
    assert np.allclose(scene.distance([[0.5, 0, 0]]), -1.3, atol=1e-5)

    via_loads = fractalc.loads(text, params={"r": 1.3, "shift": 0.5}).render(width=W, height=H)
    np.testing.assert_array_equal(via_loads.rgba, moved.rgba)
    back = fractalc.loads(text, params={"r": 1, "shift": 0}).render(width=W, height=H)
    np.testing.assert_array_equal(back.rgba, first.rgba)
    assert build_module.statistics.builds == builds


@pytest.mark.opencl
def test_same_text_and_runtime_settings_do_not_rebuild():
    text = _unique_scene()
    warm = fractalc.loads(text)
    warm.render(width=W, height=H)
    warm.distance(np.zeros((4, 3)))     # the estimate's own program (emit_distance)
    builds = build_module.statistics.builds
    scene = fractalc.loads(text)
    small = scene.render(width=W, height=H)
    large = scene.render(width=2 * W, height=H + 10)
    aa = scene.render(width=W, height=H, samples=3, seed=4)
    scene.distance(np.zeros((4, 3)))
    assert build_module.statistics.builds == builds
    assert large.depth.shape == (H + 10, 2 * W) and small.depth.shape == (H, W)
    assert not np.array_equal(aa.rgba, small.rgba)


@pytest.mark.opencl
def test_frames_share_one_kernel_and_each_renders_its_own_params_and_camera():
    """Frames reuse the scene's render kernel (taken from the program once,
    its params' and camera's buffers kept between frames, written again
    only when their values change), yet each renders its own params and
    camera: as a scene that renders nothing else does."""
    text = _unique_scene()
    scene = fractalc.loads(text)
    kernel = scene.renderer(width=W, height=H).kernel
    side = fractalc.Camera(position=(2, -3, 1.5), target=(0, 0, 0), fov=40)
    first = scene.render(width=W, height=H)
    scene.set_params({"r": 1.3})
    moved = scene.render(width=W, height=H, camera=side)
    scene.set_params({"r": 1})
    again = scene.render(width=W, height=H)
    assert scene.renderer(width=2 * W, height=H, camera=side, samples=2).kernel is kernel
    np.testing.assert_array_equal(again.rgba, first.rgba)
    alone = fractalc.loads(text, params={"r": 1.3}).render(width=W, height=H, camera=side)
    np.testing.assert_array_equal(moved.rgba, alone.rgba)
    assert not np.array_equal(moved.depth, first.depth)
    # and each frame's metadata its own params and camera
    assert first.metadata["params"] == again.metadata["params"] == "r=1 shift=0"
    assert moved.metadata["params"] == "r=1.3 shift=0"
    assert moved.metadata["camera.position"] == "2 -3 1.5" != first.metadata["camera.position"]
    assert moved.metadata["worldToCamera"] != first.metadata["worldToCamera"]


@pytest.mark.opencl
@pytest.mark.parametrize("integrator, samples", [("direct", 2), ("path", 20)])
def test_a_block_of_rows_equals_those_rows_of_the_whole_frame(integrator, samples):
    """The rendering seam (Scene.renderer) that the render farm's tiles
    use: any block of rows, not on lane-block edges, is bit for bit those
    rows of the whole frame; the path tracer's passes (16 samples, then 4)
    too."""
    renderer = fractalc.loads(LANES_SCENE).renderer(seed=3, width=W, height=H, samples=samples,
                                                    integrator=integrator, aovs=["P"])
    whole = renderer.pixels()
    for first, count in ((0, H), (5, 7), (H - 3, 3)):
        np.testing.assert_array_equal(renderer.rows(first, count), whole[first:first + count])
    image = renderer.image(whole, 0.25)
    assert image.metadata["render_seconds"] == "0.250000" and image.passes["P"].shape == (H, W, 3)


@pytest.mark.opencl
def test_compiled_settings_do_rebuild():
    """A setting compiled into the kernel (max_steps) builds a new program,
    so the no-rebuild checks above are not vacuous."""
    scene = fractalc.loads(_unique_scene())
    scene.render(width=8, height=8)
    builds = build_module.statistics.builds
    scene.render(width=8, height=8, max_steps=17)
    assert build_module.statistics.builds == builds + 1


@pytest.mark.opencl
def test_render_keyword_precision_overrides_the_file():
    """LANGUAGE.md: `render` accepts every render key as a keyword argument,
    overriding the file; `precision` is a render key."""
    text = "scene sphere(1)\ncamera { position: (0, -4, 1), target: (0, 0, 0) }"
    double = fractalc.loads(text, precision="double").render(width=W, height=H)
    keyword = fractalc.loads(text).render(width=W, height=H, precision="double")
    assert keyword.metadata["precision"] == "double"
    np.testing.assert_array_equal(keyword.depth, double.depth)


# ----------------------------------------------------------- kernel source

LIBRARY_EXTRAS = ("sd_torus", "sd_box", "soft_shadow", "hard_shadow", "ambient_occlusion",
                  "smooth_min", "twist_point")


@pytest.mark.opencl
def test_kernel_source_holds_only_what_the_scene_uses():
    source = fractalc.loads("scene sphere(1)").kernel_source()
    assert "sd_sphere" in source
    for name in LIBRARY_EXTRAS:
        assert name not in source, name


@pytest.mark.opencl
def test_kernel_source_names_are_real_library_functions():
    """The names checked for absence above do appear when a scene uses them."""
    source = fractalc.loads(textwrap.dedent("""\
        scene union(torus().twist(0.3), box(1), smooth: 0.2)
        light directional { direction: (0, 0, -1), shadows: soft }
        light point { position: (0, 0, 3), shadows: hard }
        render { ao: 0.5 }
        """)).kernel_source()
    for name in LIBRARY_EXTRAS:
        assert re.search(rf"\b{name}\s*\(", source), name


@pytest.mark.opencl
def test_kernel_source_of_shadows_and_ao():
    source = fractalc.loads(textwrap.dedent("""\
        scene sphere(1) | plane(offset: -1)
        light directional { direction: (0, 0, -1), shadows: soft }
        render { ao: 0.5 }
        """)).kernel_source()
    assert "soft_shadow" in source and "ambient_occlusion" in source
    assert "hard_shadow" not in source


FLOAT_LITERAL = re.compile(r"(?<![\w.])(?:\d+\.\d*|\.\d+|\d+(?=[eE]))(?:[eE][+-]?\d+)?[fF]\b")


@pytest.mark.opencl
def test_double_source_has_no_float_literals():
    text = textwrap.dedent("""\
        scene union(sphere(1.5), torus(0.75, 0.125).twist(0.5), smooth: 0.25) | plane(offset: -1e-3)
        light directional { direction: (0, 0, -1), shadows: soft }
        render { ao: 0.5, epsilon: 1e-4 }
        """)
    single = fractalc.loads(text).kernel_source()
    double = fractalc.loads(text, precision="double").kernel_source()
    assert len(FLOAT_LITERAL.findall(single)) > 10       # the regex finds them
    assert FLOAT_LITERAL.findall(double) == []
    assert "#define PRECISION_DOUBLE 1" in double
    assert re.search(r"#pragma OPENCL EXTENSION cl_khr_fp64 *: *enable", double)
    assert "`real` is double" in double[:double.index("#define")]   # the header says so
    assert "#define PRECISION_DOUBLE 0" in single


UNSUFFIXED_LITERAL = re.compile(r"(?<![\w.])(?:\d+\.\d*|\.\d+|\d+(?=[eE]))(?:[eE][+-]?\d+)?(?![\w.])")


def _float_code(source: str) -> str:
    """A float kernel's source without comments and without the double-only
    branches of `#if PRECISION_DOUBLE` (not compiled in float)."""
    lines, skipping = [], False
    for line in source.splitlines():
        directive = line.strip()
        if directive.startswith("#if PRECISION_DOUBLE"):
            skipping = True
        elif skipping and directive.startswith(("#else", "#endif")):
            skipping = False
        elif not skipping:
            lines.append(re.sub(r"//.*", "", line))
    return "\n".join(lines)


@pytest.mark.opencl
@pytest.mark.parametrize("example", sorted(p.name for p in (REPO / "examples").glob("*.frac")))
def test_float_kernels_have_no_double_literals(example):
    """An unsuffixed literal is a double in OpenCL C and promotes the
    arithmetic around it to double: every literal of a float kernel carries f."""
    code = _float_code(fractalc.load(REPO / "examples" / example).kernel_source())
    assert len(FLOAT_LITERAL.findall(code)) > 10         # the regexes see the literals
    assert UNSUFFIXED_LITERAL.findall(code) == []


# ------------------------------------------------------- standalone kernel

STANDALONE_SCENE = textwrap.dedent("""\
    param r = 0.9 in [0.5, 1.5]
    material red { color: (0.9, 0.2, 0.1), specular: 0.5, shininess: 20 }
    scene union(sphere(r).material(red), box((1.6, 0.6, 0.6)).translate((0, 0, -0.5)), smooth: 0.2) | plane(offset: -1)
    camera { position: (2.5, -3.5, 1.8), target: (0, 0, 0.6), up: (0, 0, 1), fov: 42 }
    light directional { direction: (-0.4, 0.7, -1), shadows: soft, softness: 10 }
    render { width: 64, height: 48, ao: 0.5 }
    """)

STANDALONE_RUNNER = textwrap.dedent("""\
    # Runs a fractalc-compiled kernel with bare pyopencl (no fractalc import).
    import json, re, sys
    import numpy as np
    import pyopencl as cl

    source_path, spec_path, out_path = sys.argv[1:4]
    spec = json.load(open(spec_path))
    source = open(source_path).read()
    header = source[:source.index("#define")]
    lanes = int(re.search(r"LANES = (\\d+)", header).group(1))
    block_x = int(re.search(r"#define LANES_X (\\d+)", source).group(1))
    block_y = int(re.search(r"#define LANES_Y (\\d+)", source).group(1))
    scalar = np.float64 if "__constant double *params" in header else np.float32

    position = np.array(spec["position"], dtype=np.float64)
    forward = np.array(spec["target"], dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.array(spec["up"], dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_half = np.tan(np.radians(spec["fov"]) / 2)
    camera = np.array([*position, *forward, *right, *up, tan_half], dtype=scalar)
    # the scene's params, then the slots that derived_params fills from them
    slots = int(re.search(r"fills the\\s+(?://\\s+)?(\\d+) slots", source).group(1))
    params = np.array([*spec["params"], *[0.0] * slots], dtype=scalar)

    # the device fractalc rendered on, by its platform's and its own name
    device = next(d for platform in cl.get_platforms() if platform.name == spec["platform"]
                  for d in platform.get_devices() if d.name == spec["device"])
    context = cl.Context([device])
    queue = cl.CommandQueue(context)
    program = cl.Program(context, source).build()
    width, height = spec["width"], spec["height"]
    pitch = -(-width // block_x) * block_x
    rows = -(-height // block_y) * block_y
    out = np.empty((rows, pitch, 9), dtype=np.float32)
    mf = cl.mem_flags
    out_buffer = cl.Buffer(context, mf.WRITE_ONLY, out.nbytes)
    params_buffer = cl.Buffer(context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=params)
    program.derived_params(queue, (1,), None, params_buffer)
    camera_buffer = cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=camera)
    program.render(queue, (pitch // block_x, rows // block_y), None, out_buffer, params_buffer,
                   camera_buffer, np.int32(width), np.int32(height), np.int32(0), np.int32(0),
                   np.int32(pitch), np.int32(1), np.uint32(0))
    cl.enqueue_copy(queue, out, out_buffer)
    queue.finish()
    assert "fractalc" not in sys.modules
    # pixel by pixel, 9 channels each: one plane per channel
    np.save(out_path, out[:height, :width].transpose(2, 0, 1))
    """)


def _cli(*args, cwd):
    env = {k: v for k, v in os.environ.items() if k != "FRACTALC_DEVICE"}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "fractalc", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.opencl
def test_standalone_kernel_matches_fractalc_render(tmp_path):
    import json
    import OpenImageIO as oiio

    (tmp_path / "scene.frac").write_text(STANDALONE_SCENE)
    result = _cli("compile", "scene.frac", "-o", "scene.cl", "--set", "r=1.1", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    result = _cli("render", "scene.frac", "-o", "out.exr", "--set", "r=1.1", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    source = (tmp_path / "scene.cl").read_text()
    assert "#include" not in source

    camera = dict(position=(2.5, -3.5, 1.8), target=(0, 0, 0.6), up=(0, 0, 1), fov=42)
    # listing the devices registers the drivers fractalc brings, for this
    # process and the runner (as an embedder's loader would list them)
    rendered_on = default_device(list_devices())
    (tmp_path / "spec.json").write_text(json.dumps({**camera, "width": W, "height": H, "params": [1.1],
                                                    "platform": rendered_on.platform, "device": rendered_on.name}))
    (tmp_path / "runner.py").write_text(STANDALONE_RUNNER)
    # the runner sees neither the repository nor an installed fractalc
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "FRACTALC_DEVICE")}
    result = subprocess.run([sys.executable, "-I", "runner.py", "scene.cl", "spec.json", "planes.npy"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    standalone = np.load(tmp_path / "planes.npy")

    image = oiio.ImageBuf(str(tmp_path / "out.exr"))
    assert image.spec().width == W and image.spec().height == H
    names = list(image.spec().channelnames)
    pixels = image.get_pixels(oiio.FLOAT)
    planes = {name: pixels[..., names.index(name)] for name in names}
    hit = np.isfinite(planes["Z"])
    assert 0.2 * hit.size < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(standalone[4]), hit)
    for index, name in enumerate("RGB"):
        np.testing.assert_allclose(standalone[index], planes[name], atol=1e-5, rtol=1e-5)
    np.testing.assert_allclose(standalone[4][hit], planes["Z"][hit], atol=1e-5, rtol=1e-5)
    np.testing.assert_allclose(standalone[8], planes["steps"])


@pytest.mark.opencl
def test_fast_math_is_float_only_and_by_default_where_the_driver_s_native_functions_are_exact():
    text = "param p = 7 in [2, 16]\nscene mandelbulb(power: p)\n"
    scene = fractalc.loads(text)
    exact_native = scene.device.lane_choice.native_exact

    def fast(**keys):
        return int(re.search(r"#define FAST_MATH (\d)", scene.kernel_source(**keys)).group(1))
    # auto: CPU lanes whose native_ functions the lane probe measured exact (PoCL's, not Intel's)
    assert fast() == int(exact_native and scene.lanes_in_use > 1)
    assert fast(lanes=16) == 0 and fast(lanes=1) == 0, "no device given: the exact functions"
    assert fast(lanes=1, fast_math="on") == 1 and fast(lanes=16, fast_math="off") == 0
    # OpenCL has no double native_ functions: a double kernel is exact
    assert fast(lanes=16, precision="double", fast_math="on") == 0
    double = fractalc.loads(text, precision="double")
    np.testing.assert_array_equal(double.render(width=24, height=16, fast_math="on").rgba,
                                  double.render(width=24, height=16, fast_math="off").rgba)
    # at power 7 (the trigonometric iteration) exact native_ functions move
    # the distance by float rounding only (PoCL: 2.1e-6); Intel's approximate
    # ones by 6.3e-4, which is why auto leaves them out there
    points = np.random.default_rng(3).uniform(-1.2, 1.2, (4000, 3))
    exact = fractalc.loads(text + "render { fast_math: off }").distance(points)
    native = fractalc.loads(text + "render { fast_math: on }").distance(points)
    moved = np.max(np.abs(native - exact) / np.maximum(np.abs(exact), 1))
    assert moved < (1e-5 if exact_native else 3e-3)
    assert moved > 0 or scene.device.info.kind == "GPU"


# ------------------------------------------------------- the scene's bound

BOUND_SCENES = {   # name: (scene, whether the scene has a bound)
    "plane minus a ball": ("subtract(plane(offset: -1), sphere(1.5))", False),   # a ground alone
    "a ball minus a plane": ("subtract(sphere(1.5), plane(offset: 0.5))", True),
    "a ball on the ground": ("sphere(1).translate((0, 0, 1)) | plane()", True),
    "a moved, turned, rounded ground": ("union(box(1).round(0.1), plane(normal: (0.2, 0.1, 1), offset: -1)"
                                        ".translate((0, 0, 0.3)).rotate((0, 0, 1), 30).round(0.05), "
                                        "smooth: 0.2)", True),
    "a ground cut to a disc": ("intersect(plane(), sphere(2)) | torus(1, 0.3).translate((0, 0, 0.5))", True),
    "an onion shell": ("sphere(1).onion(0.3).translate((0, 0, 0.5))", True),
    "an onion ground": ("sphere(0.5) | plane(offset: -1).onion(0.2)", True),
}
# far below every ground and inside it, and unbounded: no bound for the scene
UNBOUNDED = " | sphere(0.1).translate((0, 0, -60)).repeat((300, 300, 0))"


@pytest.mark.opencl
@pytest.mark.parametrize("shape", sorted(BOUND_SCENES))
def test_the_scene_bound_changes_nothing_but_the_work(shape):
    """Rays start and end at the scene's bounding sphere, and skip it
    altogether once clear of its ground half-spaces: the image is the
    unbounded scene's, for less marching."""
    def scene(text):
        return fractalc.loads(textwrap.dedent(f"""\
            scene {text}
            camera {{ position: (0.5, -6, 2.5), target: (0, 0, 0.5) }}
            light directional {{ direction: (-0.4, 0.5, -1), shadows: hard }}
            render {{ width: 64, height: 48, epsilon: 1e-4, max_distance: 40, dither: 0 }}
            """))
    text, has_bound = BOUND_SCENES[shape]
    bounded, unbounded = scene(text), scene(text + UNBOUNDED)
    defined = re.compile(r"^real scene_bound\(", re.M)
    assert bool(defined.search(bounded.kernel_source())) == has_bound
    assert not defined.search(unbounded.kernel_source())
    a, b = bounded.render(), unbounded.render()
    hit = np.isfinite(a.depth)
    assert 0.05 < hit.mean() < 0.95
    assert (hit != np.isfinite(b.depth)).sum() <= 1
    both = hit & np.isfinite(b.depth)
    assert np.abs(a.depth[both] - b.depth[both]).max() < 1e-3
    assert np.mean(np.abs(a.rgba - b.rgba) > 1e-3) < 0.01
    assert a.steps.sum() < b.steps.sum() if has_bound else a.steps.sum() == b.steps.sum()


@pytest.mark.parametrize("decls, expected", [
    ("", (True, True)),                                           # camera and shadow rays use it
    ("render { glow: { strength: 0.5 } }", (False, False)),       # glow marches every ray in full
    ("render { glow: { strength: 0.5 } }\nlight directional { direction: (0, 0, -1), shadows: hard }",
     (True, True)),                                               # ... but shadow rays still stop
])
@pytest.mark.opencl
def test_the_bound_is_in_the_kernel_only_where_used(decls, expected):
    source = fractalc.loads(f"scene sphere(1) | plane()\n{decls}").kernel_source()
    defined = tuple(bool(re.search(rf"^\w+ {name}\(", source, re.M))
                    for name in ("scene_bound", "clear_of_half_spaces"))
    assert defined == expected
