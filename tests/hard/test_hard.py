"""Hard cases: the scene files of this folder, rendered tiny (at most 48 x 36).

Each render must give finite planes (+inf depth only where a ray missed),
the same image in float and in double, and pass one check that fails when
its case goes wrong: the camera a hair
from a fractal, rays grazing a plane, the camera inside a solid, fractal
parameters at their edges (power 2, 64 iterations, bailout 1e6, a negative
Mandelbox scale) against the numpy sphere tracer of tests/test_fractals.py,
and points a million units away, in float and in double.
"""
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc.count import count
import reference_fractals as ref
from fractalc.program import RenderSettings
from fractalc.sweep import compare
from fractalc.write import linear_to_srgb
from test_effects import ray_sphere
from test_fractals import bounded_reference_de, primary_rays, sphere_trace

pytestmark = pytest.mark.opencl

HERE = Path(__file__).resolve().parent
PRECISIONS = ("float", "double")


@lru_cache(maxsize=None)
def scene(name, precision="float"):
    return fractalc.load(HERE / f"{name}.frac", precision=precision)


@lru_cache(maxsize=None)
def rendered(name, precision="float"):
    return scene(name, precision).render()


def rays(s):
    """The camera position and the pixel-centre ray directions (H, W, 3) of a
    scene, from LANGUAGE.md's camera model."""
    c, r = s.checked.camera, s.checked.render
    return primary_rays(c.position, c.target, c.up, c.fov, r.width, r.height)


def pixel_angle(s):
    return 2 * np.tan(np.radians(s.checked.camera.fov) / 2) / s.checked.render.height


def assert_finite_planes(image):
    for name, plane in (("rgba", image.rgba), ("normal", image.normal), ("steps", image.steps)):
        assert np.isfinite(plane).all(), f"{name} has NaN or Inf"
    assert not np.isnan(image.depth).any() and (image.depth >= 0).all()
    assert np.isposinf(image.depth[~np.isfinite(image.depth)]).all()


@pytest.mark.parametrize("name", sorted(p.stem for p in HERE.glob("*.frac")))
def test_every_plane_is_finite(name):
    for precision in PRECISIONS:
        assert_finite_planes(rendered(name, precision))


# Pixels that rounding decides, per 1000 (knife edges, below), where a
# scene has more than the 2 of a shadow ray grazing an occluder: a camera a
# hair from the Mandelbulb sees it at the float estimate's limit, where its
# rounding turns the normal by a degree or more at a pixel in ten, and in a
# crevice that moves the occlusion samples in or out of the solid. Measured
# on 99x75 renders of the view and of 7 views 2e-5 away, Intel's runtime
# and PoCL 3.1: 12 to 60 pixels of 7425 (0.16-0.81%) with the power-8 step
# of d38c162, 12 to 59 with today's (whose float normals are nearer
# double's: median 0.073 against 0.089 degrees); on the 33x25 view, 0 to
# 4 of 825, so a limit of 2 in 1000 failed the older code in 1 (Intel)
# and 3 (PoCL) of the 8 views.
KNIFE_EDGES_PER_1000 = {"near_mandelbulb": 10}


@pytest.mark.parametrize("name", sorted(p.stem for p in HERE.glob("*.frac")))
def test_float_and_double_shade_alike(name):
    # at these scales rounding moves nothing visible: the same hits and the
    # same colours, shadow rays and occlusion included, but for a shadow ray
    # that grazes an occluder within the hit threshold, which rounding
    # decides (a knife edge: on mandelbox_scale_minus_1_5, moving the camera
    # by 0.002 put one such pixel of 1728 in the image in 1 to 3 of 8 views,
    # with or without cone marching); at most 2 pixels in 1000 may flip
    # (KNIFE_EDGES_PER_1000 where a scene has more)
    float_, double = rendered(name), rendered(name, "double")
    error = compare(float_, double)
    assert error.hit_mismatch <= 0.01, error
    difference = linear_to_srgb(float_.rgba[..., :3].astype(np.float64)) - linear_to_srgb(
        double.rgba[..., :3].astype(np.float64))
    knife_edges = np.abs(difference).max(axis=-1) > 0.1
    assert knife_edges.mean() <= KNIFE_EDGES_PER_1000.get(name, 2) / 1000, error
    assert np.sqrt(np.mean(difference[~knife_edges] ** 2)) < 0.005, error


# ---------------------------------------------------------- the camera 1e-3 from a surface

NEAR = 1e-3     # the camera's distance to the target, a surface point


def test_camera_a_hair_from_the_mandelbulb_sees_its_surface_at_that_distance():
    s = scene("near_mandelbulb")
    camera = np.asarray(s.checked.camera.position)
    assert np.linalg.norm(np.subtract(s.checked.camera.target, camera)) == pytest.approx(NEAR, rel=1e-6)
    assert 0 < ref.mandelbulb(camera[None])[0] < NEAR      # outside, and the surface is near
    float_, double = rendered("near_mandelbulb"), rendered("near_mandelbulb", "double")
    height, width = float_.depth.shape
    for image in (float_, double):
        assert np.isfinite(image.depth).all(), "the surface fills the view"
        # the centre ray runs to the target: it stops within a few hit
        # thresholds (a pixel's footprint, 3% of the distance) before it
        assert image.depth[height // 2, width // 2] == pytest.approx(NEAR, rel=0.1)
        assert image.depth.max() < 20 * NEAR
        lengths = np.linalg.norm(image.normal, axis=-1)
        assert np.all(np.abs(lengths - 1) < 1e-3)
        _, directions = rays(s)
        facing = np.sum(image.normal * directions, axis=-1) < 0
        # Measured 0.919 (float) and 0.918 (double), PoCL and Intel's runtime
        # alike, with the default tetrahedral normals (4 evaluations: a
        # one-sided estimate at each corner of a tetrahedron, so a fold of
        # the surface within the offset tips more of them away); central
        # differences, the default the 0.95 here was set with (before the
        # sweep chose tetrahedral, 94c4ab7), measure 0.976 / 0.975: below.
        assert facing.mean() > 0.9, "normals face the camera (but in the folds of the surface)"
    central = s.render(normals="central")
    assert (np.sum(central.normal * rays(s)[1], axis=-1) < 0).mean() > 0.95, "central differences face it"
    # float resolves this close-up as double does: same depths, same normals
    relative = np.abs(float_.depth - double.depth) / double.depth
    assert np.median(relative) < 1e-3 and np.percentile(relative, 95) < 0.05
    cosines = np.sum(float_.normal * double.normal, axis=-1)
    assert np.percentile(cosines, 5) > np.cos(np.radians(1))


# ---------------------------------------------------------- grazing rays along a plane

def grazing_prediction(s, overrelax):
    """For each pixel ray from height h towards the plane z = 0 at slope
    -dir.z, the march of LANGUAGE.md with a fixed threshold e and steps of
    w = overrelax times the distance: its height after k steps is
    h (1 - w slope)^k, it hits at the first height below e, taking k + 1
    distance evaluations, at t = (h - height) / slope. (Over-relaxation
    falls back to plain steps only when w slope > 2 - w, steeper than any
    ray here.)"""
    origin, directions = rays(s)
    h, epsilon = origin[2], s.checked.render.epsilon
    slope = -directions[..., 2]
    assert overrelax * slope.max() < 2 - overrelax
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.ceil(np.log(epsilon / h) / np.log1p(-overrelax * slope))
    k = np.where(slope > 0, k, np.inf)
    t = (h - h * (1 - overrelax * slope) ** k) / np.where(slope > 0, slope, 1)
    return slope, k + 1, np.where(slope > 0, t, np.inf)


@pytest.mark.parametrize("overrelax", [1.0, RenderSettings().overrelax])
@pytest.mark.parametrize("precision", PRECISIONS)
def test_grazing_rays_hit_the_plane_where_the_march_predicts(precision, overrelax):
    s = scene("grazing_plane", precision)
    image = s.render(overrelax=overrelax, cone_marching="off")     # the prediction is one ray's march
    slope, steps, depth = grazing_prediction(s, overrelax)
    render = s.checked.render
    reached = (steps <= render.max_steps - 1) & (depth < render.max_distance)
    out_of_steps = (slope > 0) & (steps >= render.max_steps + 2)
    assert reached.sum() >= 200 and out_of_steps.any()
    hit = np.isfinite(image.depth)
    assert hit[reached].all(), "rays that reach the plane within max_steps hit it"
    assert not hit[slope <= 0].any(), "rays level with or above the horizon miss"
    assert not hit[out_of_steps].any(), "rays that need more than max_steps miss"
    assert np.all(np.abs(image.steps[reached] - steps[reached]) <= 1)
    # the hit lies within the threshold above the plane: the analytic
    # intersection minus at most epsilon / slope
    origin, directions = rays(s)
    height = origin[2] + image.depth[reached] * directions[reached][:, 2]
    assert np.all(height < render.epsilon * 1.0001) and np.all(height > -1e-5)
    assert np.allclose(image.depth[reached], depth[reached], rtol=1e-4, atol=1e-5)


def test_cone_marched_grazing_rays_hit_the_plane_and_save_steps():
    """Cone marching (a packet of rays marched as one cone first, the
    default with CPU lanes) on rays grazing a plane: every ray that one ray's
    march brings to the plane within max_steps still hits it, within the
    threshold above it, none above the horizon hits, and the packets take
    fewer evaluations in all (a cone step is one for all its rays)."""
    s = scene("grazing_plane")
    if s.lanes_in_use == 1:
        pytest.skip("one ray per work-item: no packet to cone-march")
    render = s.checked.render
    slope, steps, _ = grazing_prediction(s, render.overrelax)
    reached = (steps <= render.max_steps - 1) & (steps < 100)
    cone = s.render(cone_marching="on")
    hit = np.isfinite(cone.depth)
    assert reached.sum() >= 200 and hit[reached].all()
    assert not hit[slope <= 0].any()
    origin, directions = rays(s)
    height = origin[2] + cone.depth[hit] * directions[hit][:, 2]
    assert np.all(height < render.epsilon * 1.0001) and np.all(height > -1e-5)
    text = (HERE / "grazing_plane.frac").read_text()
    evaluations = {c: count(fractalc.loads(text.replace("render {", f"render {{ cone_marching: {c},")))
                   .evaluations["camera"] for c in ("on", "off")}
    assert evaluations["on"] < 0.9 * evaluations["off"], evaluations


@pytest.mark.parametrize("name", sorted(p.stem for p in HERE.glob("*.frac") if not p.stem.startswith("inside_")))
def test_cone_marching_leaves_each_hard_case_as_it_was(name):
    # (a camera inside a solid marches nothing: see below)
    """The same image with the cone as without, within the error that one
    ray's march itself has: against a reference (double, a tenth of the
    threshold, plain steps, no cone), the cone's hit mismatch is no worse
    (but for one pixel), its depth p99 within 2% and its colour RMSE within
    the 1% that issue 13 allows."""
    s = scene(name)
    render = s.checked.render
    reference = scene(name, "double").render(epsilon_scale=0.1, max_steps=4 * render.max_steps,
                                             overrelax=1.0, cone_marching="off")
    cone, rays_alone = (compare(s.render(cone_marching=c), reference) for c in ("on", "off"))
    assert cone.hit_mismatch <= rays_alone.hit_mismatch + 1 / (render.width * render.height), (cone, rays_alone)
    if np.isfinite(rays_alone.depth_error_p99):
        assert cone.depth_error_p99 <= 1.02 * rays_alone.depth_error_p99, (cone, rays_alone)
    assert cone.color_rmse <= 1.01 * rays_alone.color_rmse, (cone, rays_alone)


# ---------------------------------------------------------- the camera inside a solid

@pytest.mark.parametrize("name", ["inside_sphere_centre", "inside_mandelbulb"])
def test_camera_inside_hits_everything_at_zero(name):
    s = scene(name)
    assert s.distance(np.array([s.checked.camera.position], dtype=float))[0] <= 0
    image = rendered(name)
    # one evaluation at t = 0 per ray, and with CPU lanes first the packet's
    # cone's there (which finds the camera inside: a march step of its rays)
    assert np.all(image.depth == 0) and np.all(image.steps == (2 if s.lanes_in_use > 1 else 1))
    assert np.all(image.rgba[..., 3] == 1) and image.rgba[..., :3].max() < 20


# ---------------------------------------------------------- fractal parameters at their edges

EDGE_CASES = {
    "power_2": ("mandelbulb", dict(power=2.0)),
    "iterations_64": ("mandelbulb", dict(iterations=64)),
    "bailout_1e6": ("mandelbulb", dict(bailout=1e6)),
    "mandelbox_scale_minus_1_5": ("mandelbox", dict(scale=-1.5)),
}


@pytest.mark.parametrize("name", EDGE_CASES)
def test_edge_parameters_match_the_numpy_sphere_tracer(name):
    fractal, kwargs = EDGE_CASES[name]
    s = scene(name)
    render = s.checked.render
    origin, directions = rays(s)
    expected, _ = sphere_trace(lambda p: bounded_reference_de(fractal, p, **kwargs), origin, directions,
                               render.epsilon, render.max_steps, render.max_distance)
    image = rendered(name)
    hit, expected_hit = np.isfinite(image.depth), np.isfinite(expected)
    assert 0.1 < expected_hit.mean() < 0.9, "the view holds the fractal and the background"
    assert np.mean(hit == expected_hit) >= 0.98
    both = hit & expected_hit
    difference = np.abs(image.depth[both] - expected[both])
    assert np.median(difference) < render.epsilon and np.percentile(difference, 95) < 5 * render.epsilon


def test_large_bailout_keeps_distances_finite_and_right_far_away():
    # r^8 of a point at 1e6 is 1e48: past float's range before the bailout stops it
    points = np.array([(1e6, 0, 0), (0, -3e5, 4e5), (2, 2, 2)])
    for precision in PRECISIONS:
        d = scene("bailout_1e6", precision).distance(points)
        assert np.isfinite(d).all() and (d > 0).all()
        # beyond its bound the fractal is the bounding sphere (radius 2^(1/7))
        assert d[:2] == pytest.approx(np.linalg.norm(points[:2], axis=1) - 2 ** (1 / 7), rel=1e-6)


# ---------------------------------------------------------- points a million units away

FAR_SCENES = {
    # name: (text, sphere centre)
    "far camera": ("""scene sphere(1)
        camera { position: (0, -1000000, 0), target: (0, 0, 0), fov: 0.00015 }
        render { width: 48, height: 36, max_distance: 2000000 }""", (0.0, 0.0, 0.0)),
    "far shape": ("""scene sphere(1).translate((1000000, 0, 0))
        camera { position: (1000000, -4, 1), target: (1000000, 0, 0), fov: 40 }
        render { width: 48, height: 36 }""", (1e6, 0.0, 0.0)),
}
ULP = {"float": float(np.finfo(np.float32).eps), "double": float(np.finfo(np.float64).eps)}


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("case", FAR_SCENES)
def test_a_million_units_away(case, precision):
    text, centre = FAR_SCENES[case]
    s = fractalc.loads(text, precision=precision)
    image = s.render()
    assert_finite_planes(image)
    scale = 1e6 * ULP[precision]             # the spacing of numbers near 1e6
    # distances at points about 1e6 from the origin: |p - c| - R, up to the
    # rounding of their coordinates
    rng = np.random.default_rng(5)
    points = np.concatenate([np.asarray(centre) + rng.normal(size=(64, 3)) * 3, rng.normal(size=(16, 3)) * 1e6])
    exact = np.linalg.norm(points - centre, axis=1) - 1
    assert np.allclose(s.distance(points), exact, rtol=4 * ULP[precision], atol=2 * scale)
    # the image: a ray that meets the sphere hits it; one that passes it by
    # more than twice the hit threshold (a pixel's footprint there) misses;
    # float may move the surface by the rounding of coordinates of 1e6
    origin, directions = rays(s)
    offset = np.asarray(centre) - origin
    passing = np.linalg.norm(np.cross(directions, offset), axis=-1)      # closest approach to the centre
    threshold = (directions @ offset) * pixel_angle(s)
    rounding = 0 if precision == "double" else 2 * scale
    must_hit, must_miss = passing < 1 - rounding, passing > 1 + 2 * threshold + rounding
    hit = np.isfinite(image.depth)
    assert 0.1 < must_hit.mean() < 0.8, "the sphere is in view"
    assert hit[must_hit].all() and not hit[must_miss].any()
    # depth on the sphere's face (away from its rim): a ray stops where the
    # distance falls below the threshold, at most threshold / cos(incidence)
    # before the surface; and the image's Z is float32 whatever the
    # precision, whose spacing near 1e6 is 1/16 (0.86 thresholds of the far
    # camera: its double depths measured up to 2.07 thresholds off, within
    # 0.93 of this bound, PoCL and Intel's runtime alike)
    face = passing < 0.9
    expected = ray_sphere(origin, directions, centre, 1.0)
    error = np.abs(image.depth[face] - expected[face])
    incidence = np.sqrt(1 - passing[face] ** 2)
    stored = 0.5 * np.spacing(expected[face].astype(np.float32)).astype(np.float64)
    assert np.all(error <= threshold[face] / incidence + stored + 2 * rounding)
