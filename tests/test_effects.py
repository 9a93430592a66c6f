"""Optical effects, measured: every test renders a tiny image (64 x 48, a
few at 128 x 96) and compares numbers taken from it (colours, the depth,
normal and steps AOVs) with what the effect's formula or the scene's
geometry predicts, computed here in numpy from LANGUAGE.md's camera model.
The last tests check that each effect's code is in the kernel exactly when
the scene uses it. docs/effects.md describes the effects; its examples are
checked at the end.

Lighting is chosen so that colours are easy to predict: a directional light
of intensity 0 and no lights' shadows leaves only the ambient term,
0.25 * albedo * occlusion (`AMBIENT` in fractalc/emit.py), so a surface of
albedo (4, 4, 4) shows exactly 1 and the default albedo 0.8 shows 0.2.
"""

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc.emit import AMBIENT, AO_DELTA

REPO = Path(__file__).resolve().parents[1]
W, H = 64, 48
FLAT_LIGHT = "light directional { direction: (0, 0, -1), intensity: 0, shadows: none }"


# ------------------------------------------------------------------ helpers

def vec(v) -> str:
    return "(" + ", ".join(repr(float(c)) for c in v) + ")"


class Camera:
    """LANGUAGE.md's camera model: the frame, the ray through a pixel
    position, and the pixel a world point projects to."""

    def __init__(self, position, target, up=(0, 0, 1), fov=45.0, width=W, height=H):
        self.position = np.asarray(position, dtype=np.float64)
        self.target = np.asarray(target, dtype=np.float64)
        self.up_given = np.asarray(up, dtype=np.float64)
        self.fov = float(fov)
        self.width, self.height = width, height
        forward = self.target - self.position
        self.forward = forward / np.linalg.norm(forward)
        right = np.cross(self.forward, self.up_given)
        self.right = right / np.linalg.norm(right)
        self.up = np.cross(self.right, self.forward)
        self.tan_half = np.tan(np.radians(self.fov) / 2)

    def text(self, extra: str = "") -> str:
        return (f"camera {{ position: {vec(self.position)}, target: {vec(self.target)}, "
                f"up: {vec(self.up_given)}, fov: {self.fov}{extra} }}")

    def sized(self, width, height) -> "Camera":
        return Camera(self.position, self.target, self.up_given, self.fov, width, height)

    @property
    def pixel_angle(self) -> float:
        """The angle one pixel subtends at the image centre (the kernel's
        `pixel_angle`, Hart's clarity function per unit distance)."""
        return 2 * self.tan_half / self.height

    def rays(self, px=None, py=None) -> np.ndarray:
        """Unit directions through pixel positions (pixel units from the
        top-left corner); by default through every pixel centre, (H, W, 3)."""
        if px is None:
            px, py = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        aspect = self.width / self.height
        x = (2 * np.asarray(px) / self.width - 1) * aspect * self.tan_half
        y = (1 - 2 * np.asarray(py) / self.height) * self.tan_half
        dirs = self.forward + x[..., None] * self.right + y[..., None] * self.up
        return dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)

    def project(self, point) -> tuple[float, float]:
        """(column, row) of the pixel whose centre ray passes through `point`
        (fractional: 0 is the centre of the first pixel)."""
        v = np.asarray(point, dtype=np.float64) - self.position
        depth = v @ self.forward
        x, y = (v @ self.right) / depth, (v @ self.up) / depth
        column = (x / (self.width / self.height * self.tan_half) + 1) * self.width / 2 - 0.5
        row = (1 - y / self.tan_half) * self.height / 2 - 0.5
        return column, row

    def hit_points(self, image) -> np.ndarray:
        """World points of the depth AOV (the origin where the ray missed)."""
        depth = np.where(np.isfinite(image.depth), image.depth, 0.0)
        return self.position + self.rays() * depth[..., None]


def render(text: str, **keys):
    keys.setdefault("width", W)
    keys.setdefault("height", H)
    return fractalc.loads(textwrap.dedent(text)).render(**keys)


def ray_sphere(origin, dirs, centre, radius):
    """Nearest ray distance to a sphere in front of the origin (+inf on a miss)."""
    oc = np.asarray(origin, dtype=np.float64) - np.asarray(centre, dtype=np.float64)
    b = np.sum(dirs * oc, axis=-1)
    c = np.sum(oc * oc, axis=-1) - radius * radius
    disc = b * b - c
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc > 0) & (t > 0), t, np.inf)


def sd_box(p, centre, size):
    q = np.abs(p - np.asarray(centre)) - np.asarray(size) / 2
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)


def impact(camera: Camera, dirs, centre=(0, 0, 0)) -> np.ndarray:
    """Distance from `centre` to each ray's line."""
    return np.linalg.norm(np.cross(dirs, np.asarray(centre) - camera.position), axis=-1)


# --------------------------------------------------------- ambient occlusion

AO_CAMERA = Camera((-2.0, -2.5, 2.0), (1.0, 0.0, 0.2), fov=50)
FLOOR = ((0, 0, -0.5), (4, 6, 1))      # centre, size: top face z = 0
WALL = ((1.5, 0, 1.5), (1, 6, 3))      # its face x = 1 meets the floor: the inner corner
AO_SCENE = f"""
    let floor = box({vec(FLOOR[1])}).translate({vec(FLOOR[0])})
    let wall = box({vec(WALL[1])}).translate({vec(WALL[0])})
    scene floor | wall
    {AO_CAMERA.text()}
    {FLAT_LIGHT}
    render {{ epsilon: 1e-4 }}
"""


def _ao_corner_and_open(image):
    p = AO_CAMERA.hit_points(image)
    hit = np.isfinite(image.depth)
    floor = hit & (np.abs(p[..., 2]) < 1e-3) & (p[..., 0] < 1)
    to_wall = 1 - p[..., 0]
    corner, open_ = floor & (to_wall < 0.05), floor & (to_wall > 1.0)
    assert corner.sum() >= 10 and open_.sum() >= 200
    return p, hit, corner, open_


@pytest.mark.opencl
@pytest.mark.parametrize("method", ["normal", "steps"])
def test_ao_darkens_the_inner_corner_more_with_strength(method):
    scene = fractalc.loads(textwrap.dedent(AO_SCENE))
    albedo = 0.8 * AMBIENT            # the default material, ambient light only
    margins = []
    for strength in (0.0, 0.25, 0.5, 1.0):
        image = scene.render(width=W, height=H, ao=strength, ao_method=method)
        p, hit, corner, open_ = _ao_corner_and_open(image)
        colour = image.rgba[..., 0].astype(np.float64)
        if method == "normal":
            # Syntopia part II / Quilez: five samples along the normal,
            # weights 1/2, 1/4, ...: sum w_i max(i delta - DE(p + n i delta), 0) / delta.
            de = lambda q: np.minimum(sd_box(q, *FLOOR), sd_box(q, *WALL))  # noqa: E731
            occlusion = sum(0.5 ** i * np.maximum(i * AO_DELTA - de(p + image.normal * i * AO_DELTA), 0)
                            for i in range(1, 6)) / AO_DELTA
            predicted = albedo * np.clip(1 - strength * occlusion, 0, 1)
            # The open plane is not occluded at all.
            assert np.allclose(colour[open_], albedo, atol=1e-6)
        else:
            predicted = albedo * np.clip(1 - strength * image.steps / (image.steps + 32), 0, 1)
        assert np.abs(colour - predicted)[hit].max() < 1e-5
        margins.append(colour[open_].mean() - colour[corner].mean())
    assert margins[0] == pytest.approx(0, abs=1e-6)          # ao 0 is off
    assert margins[1] < margins[2] < margins[3]               # grows with ao ...
    if method == "normal":
        assert margins[3] > 0.15                               # ... up to nearly black (0.2 open)
    else:
        # step-count AO is linear in ao: the corner takes more steps than the plane
        assert margins[1] > 0.002
        assert margins[3] / margins[1] == pytest.approx(4, rel=0.02)


# ------------------------------------------------------------------- shadows

# Camera straight down onto the floor z = 0; a thin plate (x in [-6, -3],
# top at z = 1.5), out of view, shades the floor from light travelling along
# (2, 0, -1): the shadow's edge, cast by the plate's top corner, is the line
# x = 0 on the floor; x < 0 is in shadow.
SHADOW_CAMERA = Camera((0, 0, 5.0), (0, 0, 0), up=(0, 1, 0), fov=40)
LIT = AMBIENT * 0.8 + 0.8 / np.sqrt(5)       # ambient + diffuse (n . l = 1/sqrt 5)
SHADED = AMBIENT * 0.8


def _shadow_scene(shadows="hard", softness=16, plate=True):
    shape = "plane() | box((3, 20, 0.1)).translate((-4.5, 0, 1.45))" if plate else "plane()"
    return f"""
        material matte {{ color: (0.8, 0.8, 0.8), specular: 0 }}
        scene ({shape}).material(matte)
        {SHADOW_CAMERA.text()}
        light directional {{ direction: (2, 0, -1), shadows: {shadows}, softness: {softness} }}
        render {{ epsilon: 1e-4 }}
    """


def _visibility(image):
    """The light's visibility per pixel and each pixel's floor x."""
    x = SHADOW_CAMERA.hit_points(image)[..., 0]
    return (image.rgba[..., 0].astype(np.float64) - SHADED) / (LIT - SHADED), x


@pytest.mark.opencl
def test_an_occluder_darkens_the_floor_behind_it():
    without = render(_shadow_scene(plate=False))
    assert np.allclose(without.rgba[..., 0], LIT, atol=1e-5)
    for shadows in ("hard", "soft"):
        with_plate = render(_shadow_scene(shadows))
        _, x = _visibility(with_plate)
        behind = x < -0.2
        assert behind.sum() > 500
        assert np.allclose(with_plate.rgba[..., 0][behind], SHADED, atol=1e-5)
        assert (without.rgba[..., 0][behind] - with_plate.rgba[..., 0][behind]).min() > 0.35
    none = render(_shadow_scene("none"))
    assert np.allclose(none.rgba[..., 0], LIT, atol=1e-5)


@pytest.mark.opencl
def test_hard_shadow_edge_is_sharp_and_where_geometry_puts_it():
    visible, x = _visibility(render(_shadow_scene("hard")))
    half_pixel = 0.5 * 5.0 * SHADOW_CAMERA.pixel_angle
    assert ((visible > 0.01) & (visible < 0.99)).sum() == 0        # no penumbra pixel at all
    assert np.all(visible[x < -half_pixel] < 0.01)
    assert np.all(visible[x > half_pixel] > 0.99)


def _soft_prediction(x, k):
    """Quilez's penumbra min_t k d(t) / t for the floor point at x > 0: the
    shadow ray passes the plate's corner at distance d0 = x / sqrt 5 after
    tc = sqrt 5 (1.5 + 0.4 x); with d(t)^2 = d0^2 + (t - tc)^2 the minimum
    of d / t is d0 / sqrt(tc^2 + d0^2)."""
    d0 = x / np.sqrt(5)
    tc = np.sqrt(5) * (1.5 + 0.4 * x)
    return np.clip(k * d0 / np.sqrt(tc ** 2 + d0 ** 2), 0, 1)


def _crossing(x, v, level):
    """x where the increasing profile v(x) first reaches `level` (linear
    interpolation between pixels)."""
    i = int(np.argmax(v >= level))
    return x[i - 1] + (level - v[i - 1]) * (x[i] - x[i - 1]) / (v[i] - v[i - 1])


@pytest.mark.opencl
def test_soft_shadow_penumbra_widens_as_softness_falls():
    widths = {}
    for k in (8, 16, 32):
        visible, x = _visibility(render(_shadow_scene("soft", k)))
        row, xs = visible[H // 2], x[H // 2]
        assert np.all(row[xs < 0] < 1e-3)                   # the umbra stays dark
        lit_side = xs > 0
        assert np.abs(row[lit_side] - _soft_prediction(xs[lit_side], k)).max() < 0.04
        widths[k] = _crossing(xs, row, 0.9) - _crossing(xs, row, 0.1)
        fine = np.linspace(0, 3, 30001)
        predicted = _crossing(fine, _soft_prediction(fine, k), 0.9) - _crossing(fine, _soft_prediction(fine, k), 0.1)
        assert widths[k] == pytest.approx(predicted, rel=0.15), (k, widths[k], predicted)
    assert widths[8] > 1.6 * widths[16] > 2.56 * widths[32]
    # the softest penumbra spans many pixels (a hard edge: none, see above)
    assert widths[8] > 8 * 5.0 * SHADOW_CAMERA.pixel_angle


# A box hollowed by a ball: concave surfaces, and a distance with kinks
# where the box's and the ball's distances meet (CSG), seen into its holes.
HOLLOW_CAMERA = Camera((2.2, -2.6, 2.0), (0, 0, 0), fov=22)
HOLLOW_LIGHT = np.array([-0.4, 0.6, -1.0])
HOLLOW_EPSILON = 1e-3


def _hollow_box_distance(p):
    q = np.abs(p) - 0.6
    box = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)
    return np.maximum(box, 0.75 - np.linalg.norm(p, axis=-1))


@pytest.mark.opencl
def test_soft_shadow_on_concave_surfaces_is_the_smallest_ratio_along_the_ray():
    """The penumbra on the hollow box is min_t k d(t) / t taken densely
    along each shadow ray (from the hit point lifted by twice the threshold,
    as the kernel does), on every pixel, and so varies as smoothly as that:
    read off the sphere-tracing samples alone it was grainy (errors up to
    0.19 jumping between neighbouring pixels: 0.16 of excess second
    difference where now 0.014)."""
    k = 8
    image = render(f"""
        material matte {{ color: (0.8, 0.8, 0.8), specular: 0 }}
        scene (box(1.2) - sphere(0.75)).material(matte)
        {HOLLOW_CAMERA.text()}
        light directional {{ direction: {vec(HOLLOW_LIGHT)}, shadows: soft, softness: {k} }}
        render {{ epsilon: {HOLLOW_EPSILON}, dither: 0 }}
    """)
    to_light = -HOLLOW_LIGHT / np.linalg.norm(HOLLOW_LIGHT)
    facing = image.normal.astype(np.float64) @ to_light
    lit = np.isfinite(image.depth) & (facing > 0.05)
    visible = (image.rgba[..., 0] - AMBIENT * 0.8) / (0.8 * np.where(lit, facing, 1))
    origins = HOLLOW_CAMERA.hit_points(image) + image.normal * 2 * HOLLOW_EPSILON
    exact = np.full(lit.shape, np.inf)
    for t in np.geomspace(2 * HOLLOW_EPSILON, 4, 3000):
        exact = np.minimum(exact, k * _hollow_box_distance(origins + to_light * t) / t)
    exact = np.clip(exact, 0, 1)
    penumbra = lit & (exact > 0.02) & (exact < 0.98)
    assert penumbra.sum() > 100 and (lit & (exact == 1)).sum() > 500 and (lit & (exact == 0)).sum() > 50
    error = np.abs(visible - exact)[lit]
    assert np.quantile(error, 0.99) < 0.02 and error.max() < 0.05, (np.quantile(error, 0.99), error.max())
    # fully lit and fully shadowed stay so
    assert np.all(visible[lit & (exact == 1)] > 1 - 1e-5) and np.all(visible[lit & (exact == 0)] < 1e-5)
    # smooth along rows: the second difference is the reference's, within noise
    rows = lit[:, 2:] & lit[:, 1:-1] & lit[:, :-2] & penumbra[:, 1:-1]
    excess = np.abs(np.diff(visible, 2, axis=1) - np.diff(exact, 2, axis=1))[rows]
    assert np.quantile(excess, 0.95) < 0.03, np.quantile(excess, 0.95)


# A ball over a floor, lit at 45 degrees: each floor point's shadow ray
# passes the ball's centre at a distance known in closed form, so both the
# edge a hard shadow draws (a ray within the hit threshold of a surface is
# blocked, as a camera ray hits it) and a soft shadow's penumbra outside the
# ball (min over t of k d(t) / t, Quilez) can be predicted per pixel.
BALL_CENTRE = np.array([0.0, 0.0, 1.6])
BALL_TO_LIGHT = np.array([-1.0, 0.0, 1.0]) / np.sqrt(2)
BALL_SOFTNESS = 16


def _ball_shadow(shadows: str, epsilon: float):
    """The shadow pass on the floor, and each floor pixel's shadow ray: its
    origin (the hit lifted by twice the threshold along the floor's normal,
    as the kernel lifts it) and how far it passes outside the ball (< 0:
    through it)."""
    image = render(f"""
        material matte {{ color: (0.8, 0.8, 0.8), specular: 0 }}
        scene (plane() | sphere(1).translate({vec(BALL_CENTRE)})).material(matte)
        camera {{ position: (1.6, -0.5, 6), target: (1.6, 0, 0), fov: 40 }}
        light directional {{ direction: {vec(-BALL_TO_LIGHT)}, shadows: {shadows}, softness: {BALL_SOFTNESS} }}
        render {{ epsilon: {epsilon} }}
    """, aovs=["P", "shadow"])
    position = image.passes["P"].astype(np.float64)
    floor = np.isfinite(image.depth) & (position[..., 2] < 0.5)
    origins = position[floor] + 2 * epsilon * np.array([0.0, 0.0, 1.0])
    along = (BALL_CENTRE - origins) @ BALL_TO_LIGHT
    passing = np.linalg.norm(BALL_CENTRE - origins - along[:, None] * BALL_TO_LIGHT, axis=-1) - 1
    return image.passes["shadow"][..., 0][floor].astype(np.float64), origins, passing


@pytest.mark.opencl
@pytest.mark.parametrize("shadows", ["hard", "soft"])
def test_a_shadow_ray_within_the_hit_threshold_of_a_surface_is_blocked(shadows):
    # with a threshold as wide as 0.1 the rays that pass the ball within it
    # span a band of pixels: all blocked, as camera rays there hit the ball
    # (a shadow hit test at a tenth of the threshold leaves them lit)
    epsilon = 0.1
    shadow, _, passing = _ball_shadow(shadows, epsilon)
    grazing = (passing > 0) & (passing < 0.8 * epsilon)
    assert grazing.sum() > 40
    assert np.all(shadow[passing < 0.8 * epsilon] == 1)
    if shadows == "hard":
        assert np.all(shadow[passing > 1.05 * epsilon] == 0)


@pytest.mark.opencl
def test_a_soft_shadow_penumbra_reaches_past_the_occluder():
    # outside the ball the light is dimmed by min_t k d(t) / t over the ray
    # (from t = 2 thresholds, as the kernel starts it); the march's bound
    # once cut the penumbra off at the sphere that holds the scene, the
    # ball itself: the shadow stopped at its silhouette
    epsilon = 0.02
    shadow, origins, passing = _ball_shadow("soft", epsilon)
    t = np.geomspace(2 * epsilon, 30, 20000)
    distance = np.linalg.norm(origins[:, None, :] + t[:, None] * BALL_TO_LIGHT - BALL_CENTRE, axis=-1) - 1
    visible = np.clip((BALL_SOFTNESS * distance / t).min(axis=-1), 0, 1)
    outside = passing > 1.05 * epsilon
    assert (outside & (visible < 0.9)).sum() > 100, "a wide penumbra"
    # measured: at most 6.9e-5 (PoCL and Intel's runtime alike)
    assert np.abs(1 - shadow - visible)[outside].max() < 3e-4


# The twisted column on a floor: a twist divides the box's distance
# by its Lipschitz factor, which grows with the distance from the twist's
# axis, so the estimate was capped near 1 / rate everywhere and a soft
# shadow's k d / t read the cap as a near miss: grey rings over the floor.
TWISTED_COLUMN = """
    scene union(box((0.5, 0.5, 2.2)).twist(1.2).translate((2.2, 0.6, 1.1)), plane())
    camera { position: (3.5, -5.5, 3.8), target: (0, 0, 0.7), fov: 42 }
    light directional { direction: (-0.4, 0.7, -1), shadows: soft, softness: 10 }
"""


def _ray_to_segment(origins, direction, a, b, reach=20.0, samples=4001):
    """The closest approach of each ray origin + t direction (0 <= t <=
    reach) to the segment a b, sampled densely along the ray."""
    t = np.linspace(0.0, reach, samples)
    points = origins[..., None, :] + t[:, None] * direction
    along = np.clip(((points - a) @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
    return np.linalg.norm(points - (a + along[..., None] * (b - a)), axis=-1).min(axis=-1)


@pytest.mark.opencl
def test_a_twisted_shape_shadows_only_the_floor_near_it():
    image = render(TWISTED_COLUMN, aovs=["P", "shadow"])
    position, shadow = image.passes["P"].astype(np.float64), image.passes["shadow"]
    floor = np.isfinite(image.depth) & (image.normal[..., 2] > 0.99) & (position[..., 2] < 0.1)
    to_light = np.array([0.4, -0.7, 1.0]) / np.linalg.norm([0.4, -0.7, 1.0])
    # how near each floor point's shadow ray passes the column's axis (the
    # column reaches 0.35 from it)
    passing = _ray_to_segment(position[floor], to_light, np.array([2.2, 0.6, 0.0]), np.array([2.2, 0.6, 2.2]))
    far = passing > 1.0
    assert far.sum() > 1000
    assert shadow[floor][far].max() < 1e-4, "the floor far from the column is fully lit"
    assert (shadow[floor][passing < 0.3] > 0.9).sum() >= 2, "the column still casts its shadow"


# ---------------------------------------------------------------------- glow

GLOW_CAMERA = Camera((0, -5.0, 0), (0, 0, 0), fov=40)
GLOW_BACKGROUND = 0.1


def _glow_scene(glow=""):
    return f"""
        scene sphere(1)
        {GLOW_CAMERA.text()}
        render {{ background: ({GLOW_BACKGROUND}, {GLOW_BACKGROUND}, {GLOW_BACKGROUND}){glow} }}
    """


@pytest.mark.opencl
def test_glow_lights_misses_by_their_closest_approach():
    strength, radius = 0.8, 0.3
    image = render(_glow_scene(f", glow: {{ color: (1, 0.5, 0.25), strength: {strength}, radius: {radius} }}"))
    plain = render(_glow_scene())
    miss = ~np.isfinite(image.depth)
    closest = impact(GLOW_CAMERA, GLOW_CAMERA.rays()) - 1.0     # true closest distance to the sphere
    red = image.rgba[..., 0].astype(np.float64)
    # channels scale with the glow colour
    glow = red - GLOW_BACKGROUND
    assert np.allclose((image.rgba[..., 1] - GLOW_BACKGROUND)[miss], 0.5 * glow[miss], atol=1e-5)
    assert np.allclose((image.rgba[..., 2] - GLOW_BACKGROUND)[miss], 0.25 * glow[miss], atol=1e-5)
    # strength * exp(-closest / radius): invert it to the closest distance
    # the march saw; sphere tracing samples the ray, so it never sees closer
    # than the truth and is within a few percent of it near the object.
    seen = -radius * np.log(glow[miss] / strength)
    truth = closest[miss]
    assert np.all(seen >= truth - 1e-4)
    near = truth < 0.5
    assert near.sum() > 300
    assert np.all(seen[near] <= truth[near] * 1.05 + 1e-3)
    assert np.all(seen <= truth * 1.10 + 1e-3)
    # near misses are brighter than far ones
    assert red[miss & (closest < 0.1)].min() > red[miss & (closest > 1.0)].max() + 0.4
    # hits are not touched: the same as with a glow too faint to see (a scene
    # without glow starts its rays at the scene's bounding sphere, so its
    # hits end elsewhere within the hit threshold)
    faint = render(_glow_scene(", glow: { color: (1, 0.5, 0.25), strength: 1e-12, radius: 0.3 }"))
    hit = ~miss
    assert np.array_equal(hit, np.isfinite(plain.depth))
    assert np.allclose(image.rgba[hit], faint.rgba[hit], atol=1e-6)


@pytest.mark.opencl
def test_glow_absent_or_zero_leaves_the_background():
    for glow in ("", ", glow: { color: (1, 0.5, 0.25), strength: 0 }"):
        image = render(_glow_scene(glow))
        miss = ~np.isfinite(image.depth)
        assert miss.sum() > 1000
        assert np.all(image.rgba[..., :3][miss] == np.float32(GLOW_BACKGROUND))


@pytest.mark.opencl
def test_glow_stays_visible_in_fog():
    """Glow and fog together: the halo must survive the fog (here thin: at
    the closest approach, about 5 away, it lets exp(-0.25) = 78% through)."""
    image = render(_glow_scene(", glow: { color: (1, 0.5, 0.25), strength: 0.8, radius: 0.3 }, "
                               "fog: { color: (0.2, 0.2, 0.2), density: 0.05 }"))
    miss = ~np.isfinite(image.depth)
    closest = impact(GLOW_CAMERA, GLOW_CAMERA.rays()) - 1.0
    red = image.rgba[..., 0]
    assert red[miss & (closest < 0.1)].mean() - red[miss & (closest > 1.0)].mean() > 0.1


# ----------------------------------------------------------------------- fog

FOG_CAMERA = Camera((0, 0, 1.0), (0, 4, 0), fov=60)
FOG_COLOUR = np.array([0.2, 0.5, 0.9])


def _fog_scene(fog=""):
    return f"""
        material red {{ color: (0.9, 0.1, 0.1), specular: 0 }}
        scene plane().material(red)
        {FOG_CAMERA.text()}
        light directional {{ direction: (0, 0, -1), shadows: none }}
        render {{ background: (0, 0, 0), max_distance: 100{fog} }}
    """


@pytest.mark.opencl
@pytest.mark.parametrize("density", [0.1, 0.3])
def test_fog_mixes_toward_its_colour_at_the_analytic_rate(density):
    clear = render(_fog_scene())
    foggy = render(_fog_scene(f", fog: {{ color: {vec(FOG_COLOUR)}, density: {density} }}"))
    hit = np.isfinite(foggy.depth)
    assert np.array_equal(hit, np.isfinite(clear.depth)) and hit.sum() > 1000
    # the plane, seen at a slant, spans depths from 1.4 to ~50
    assert foggy.depth[hit].min() < 2 and foggy.depth[hit].max() > 30
    base = clear.rgba[..., :3].astype(np.float64)
    fraction = (foggy.rgba[..., :3] - base) / (FOG_COLOUR - base)     # per channel
    expected = 1 - np.exp(-density * foggy.depth.astype(np.float64))
    assert np.abs(fraction - expected[..., None])[hit].max() < 1e-4
    # monotone convergence: far pixels are (nearly) pure fog
    far = hit & (foggy.depth > 30)
    assert np.all(fraction[far] > 1 - np.exp(-density * 30) - 1e-4)
    # misses show the fog colour
    assert np.allclose(foggy.rgba[..., :3][~hit], FOG_COLOUR, atol=1e-6)


# --------------------------------------------------------------- reflections

MIRROR_CAMERA = Camera((0, -6.0, 1.0), (0, 0, 0), fov=45)
RED_CENTRE, RED_RADIUS = np.array([0, 0, 1.0]), 0.5


def _mirror_scene(reflections, reflectivity=1.0, more=""):
    # no light: the headlight, so the sphere is lit from wherever it is seen
    return f"""
        material mirror {{ color: (0.5, 0.5, 0.5), reflectivity: {reflectivity} }}
        material red {{ color: (1, 0, 0), specular: 0 }}
        scene sphere({RED_RADIUS}).translate({vec(RED_CENTRE)}).material(red) | plane().material(mirror)
        {MIRROR_CAMERA.text()}
        render {{ reflections: {reflections}, background: (0.1, 0.1, 0.1), epsilon: 1e-4{more} }}
    """


def _mirror_prediction():
    """Pixels whose ray misses the sphere, meets the floor z = 0 and, mirrored
    there, hits the sphere."""
    dirs, origin = MIRROR_CAMERA.rays(), MIRROR_CAMERA.position
    direct = np.isfinite(ray_sphere(origin, dirs, RED_CENTRE, RED_RADIUS))
    t_floor = np.where(dirs[..., 2] < 0, -origin[2] / np.minimum(dirs[..., 2], -1e-12), np.inf)
    on_floor = np.where(np.isfinite(t_floor), t_floor, 0)[..., None] * dirs + origin
    mirrored = dirs * np.array([1, 1, -1])
    image = np.isfinite(t_floor) & ~direct & \
        np.isfinite(ray_sphere(on_floor, mirrored, RED_CENTRE, RED_RADIUS))
    return image, direct


def _red(image):
    c = image.rgba
    return (c[..., 0] - np.maximum(c[..., 1], c[..., 2])) > 0.1


@pytest.mark.opencl
def test_mirror_shows_the_sphere_where_geometry_puts_its_image():
    predicted, direct = _mirror_prediction()
    assert predicted.sum() > 40
    # the mirror image of the sphere's centre, (0, 0, -1), projects here
    column, row = MIRROR_CAMERA.project(RED_CENTRE * np.array([1, 1, -1]))
    centre = (int(round(row)), int(round(column)))
    assert predicted[centre]
    for bounces in (1, 2):
        seen = _red(render(_mirror_scene(bounces))) & ~direct
        overlap = (seen & predicted).sum() / (seen | predicted).sum()
        assert overlap > 0.95, (bounces, overlap)
        assert seen[centre]
    flat = render(_mirror_scene(0))
    assert not (_red(flat) & ~direct).any()
    assert abs(flat.rgba[centre][0] - flat.rgba[centre][1]) < 1e-6     # grey floor there


@pytest.mark.opencl
def test_partial_reflectivity_mixes_surface_and_mirror_image():
    predicted, _ = _mirror_prediction()
    own = render(_mirror_scene(0)).rgba[..., :3]
    mirror = render(_mirror_scene(1)).rgba[..., :3]
    half = render(_mirror_scene(1, reflectivity=0.5)).rgba[..., :3]
    assert np.allclose(half[predicted], 0.5 * own[predicted] + 0.5 * mirror[predicted], atol=1e-5)


# ------------------------------------------------------- depth of field, AA

# A sphere of radius 1, 6 away, flat white (ambient only) on black: the
# colour is the coverage. Its silhouette lies 6 - 1/6 along forward.
FLAT_CAMERA = Camera((0, -6.0, 0), (0, 0, 0), fov=30)
SILHOUETTE = 6 - 1 / 6


def _flat_sphere(camera_extra="", epsilon="pixel"):
    return f"""
        material flat {{ color: (4, 4, 4), specular: 0 }}
        scene sphere(1).material(flat)
        {FLAT_CAMERA.text(camera_extra)}
        {FLAT_LIGHT}
        render {{ background: (0, 0, 0), epsilon: {epsilon} }}
    """


def _edge_width(image, camera=FLAT_CAMERA):
    """Mean width in pixels of the band of partly covered pixels around the
    silhouette: their number over the silhouette's length in pixels."""
    coverage = image.rgba[..., 0]
    partial = ((coverage > 0.02) & (coverage < 0.98)).sum()
    radius = np.tan(np.arcsin(1 / 6)) / camera.tan_half * camera.height / 2
    return partial / (2 * np.pi * radius)


@pytest.mark.opencl
def test_depth_of_field_blurs_out_of_focus_edges_by_the_circle_of_confusion():
    focus = 3.0
    widths = []
    for aperture in (0.2, 0.4, 0.8):
        image = render(_flat_sphere(f", aperture: {aperture}, focus: {focus}"), samples=32)
        # thin lens: a point at depth z images to a disc of angular
        # diameter aperture * |1/z - 1/focus|
        coc = aperture * abs(1 / SILHOUETTE - 1 / focus) / FLAT_CAMERA.pixel_angle
        widths.append(_edge_width(image))
        assert widths[-1] == pytest.approx(coc, rel=0.25), (aperture, widths[-1], coc)
        # the AOVs still come from the pinhole ray
        assert np.isfinite(image.depth).sum() == np.isfinite(render(_flat_sphere()).depth).sum()
    assert widths[0] < widths[1] < widths[2]
    assert widths[2] > 3 * widths[0]


@pytest.mark.opencl
def test_depth_of_field_keeps_the_focused_edge_sharp():
    pinhole = _edge_width(render(_flat_sphere(), samples=32))
    focused = _edge_width(render(_flat_sphere(f", aperture: 0.8, focus: {SILHOUETTE}"), samples=32))
    blurred = _edge_width(render(_flat_sphere(", aperture: 0.8, focus: 3"), samples=32))
    assert pinhole < 1.5 and focused < 1.5
    assert blurred > 6 * focused


@pytest.mark.opencl
def test_sixteen_samples_cut_the_edge_error_at_least_fourfold():
    width, height = 128, 96
    camera = FLAT_CAMERA.sized(width, height)
    scene = fractalc.loads(textwrap.dedent(_flat_sphere(epsilon="1e-4")))
    reference = scene.render(width=width, height=height, samples=64, seed=99).rgba[..., 0]
    # the reference against the exact coverage (16 x 16 rays a pixel)
    n = 16
    sub = (np.arange(n) + 0.5) / n
    px, py = np.meshgrid((np.arange(width)[:, None] + sub).ravel(), (np.arange(height)[:, None] + sub).ravel())
    covered = impact(camera, camera.rays(px, py)) < 1
    exact = covered.reshape(height, n, width, n).mean(axis=(1, 3))
    assert np.sqrt(np.mean((reference - exact) ** 2)) < 0.006

    def error(samples, seed):
        image = scene.render(width=width, height=height, samples=samples, seed=seed).rgba[..., 0]
        return np.mean((image - reference) ** 2)
    one = np.sqrt(error(1, 0))
    sixteen = np.sqrt(np.mean([error(16, seed) for seed in (0, 1, 2)]))
    assert one / sixteen >= 4, (one, sixteen)


# -------------------------------------------------------------- transparency

GLASS_CAMERA = Camera((0, -6.0, 0), (0, 0, 0), fov=30)
WALL_FRONT, WALL_HALF = 3.9, 2.0       # the wall: y in [3.9, 4.1], |x|, |z| <= 2
LEFT, RIGHT = (4, 0, 0), (0, 0, 4)     # albedo 4: shows as pure 1 under ambient light


def _glass_scene(left=LEFT, right=RIGHT, transparency=1.0, ior=1.5, more=""):
    return f"""
        material glass {{ color: (0.1, 0.8, 0.1), transparency: {transparency}, ior: {ior}, specular: 0 }}
        material l {{ color: {vec(left)}, specular: 0 }}
        material r {{ color: {vec(right)}, specular: 0 }}
        let wall = box((4, 0.2, 4)).translate((0, 4, 0))
        scene sphere(1).material(glass) | intersect(wall, plane((1, 0, 0))).material(l)
              | intersect(wall, plane((-1, 0, 0))).material(r)
        {GLASS_CAMERA.text()}
        {FLAT_LIGHT}
        render {{ background: (0, 0, 0), epsilon: 1e-4{more} }}
    """


def _refract(d, n, eta):
    cos_in = -np.sum(d * n, axis=-1, keepdims=True)
    k = 1 - eta ** 2 * (1 - cos_in ** 2)
    bent = eta * d + (eta * cos_in - np.sqrt(np.maximum(k, 0))) * n
    return bent / np.linalg.norm(bent, axis=-1, keepdims=True)


def _through_the_sphere(ior):
    """Where each pixel-centre ray through the unit sphere meets the wall
    after refracting in and out (Snell, no internal bounce): the wall's x
    there (nan where it misses the wall), and the pixels considered."""
    dirs, origin = GLASS_CAMERA.rays(), GLASS_CAMERA.position
    inside = impact(GLASS_CAMERA, dirs) < 0.97
    t_in = np.where(inside, ray_sphere(origin, dirs, (0, 0, 0), 1.0), 0)
    entry = origin + dirs * t_in[..., None]
    inner = _refract(dirs, entry, 1 / ior)
    t_out = -2 * np.sum(inner * entry, axis=-1)            # chord of the unit sphere
    exit_ = entry + inner * t_out[..., None]
    out = _refract(inner, -exit_, ior)
    s = (WALL_FRONT - exit_[..., 1]) / out[..., 1]
    at = exit_ + out * s[..., None]
    on_wall = (np.abs(at[..., 0]) < WALL_HALF) & (np.abs(at[..., 2]) < WALL_HALF)
    return np.where(on_wall, at[..., 0], np.nan), inside


def _classify(rgb):
    """1 = left material seen, -1 = right, 0 = background, 9 = anything else."""
    red, blue = rgb[..., 0], rgb[..., 2]
    return np.select([(red > 0.9) & (blue < 0.1), (blue > 0.9) & (red < 0.1), (red < 0.1) & (blue < 0.1)],
                     [1, -1, 0], 9)


@pytest.mark.opencl
@pytest.mark.parametrize("ior", [1.0, 1.5])
def test_transparent_sphere_shows_the_refracted_wall(ior):
    x_wall, inside = _through_the_sphere(ior)
    clear = inside & (np.isnan(x_wall) | ((np.abs(x_wall) > 0.1) & (np.abs(x_wall) < WALL_HALF - 0.1)))
    expected = np.where(np.isnan(x_wall), 0, np.where(x_wall < 0, 1, -1))
    seen = _classify(render(_glass_scene(ior=ior)).rgba[..., :3])
    agree = (seen == expected)[clear].mean()
    assert clear.sum() > 400 and agree > 0.97, agree


@pytest.mark.opencl
def test_ball_lens_inverts_left_and_right():
    """A glass ball (focal length n R / 2(n - 1) = 1.5 from its centre) makes
    an inverted image of the wall 4 behind it; without bending (ior 1) the
    wall is seen the right way round."""
    row, left_of_centre, right_of_centre = H // 2, W // 2 - 6, W // 2 + 5
    bent = _classify(render(_glass_scene(ior=1.5)).rgba[..., :3])
    straight = _classify(render(_glass_scene(ior=1.0)).rgba[..., :3])
    assert straight[row, left_of_centre] == 1 and straight[row, right_of_centre] == -1
    assert bent[row, left_of_centre] == -1 and bent[row, right_of_centre] == 1


@pytest.mark.opencl
def test_what_is_behind_the_glass_changes_what_is_seen_through_it():
    _, inside = _through_the_sphere(1.5)
    first = render(_glass_scene()).rgba[..., :3]
    swapped = render(_glass_scene(left=RIGHT, right=LEFT)).rgba[..., :3]
    # every pixel through the ball that saw red now sees blue and vice versa
    a, b = _classify(first)[inside], _classify(swapped)[inside]
    coloured = (a == 1) | (a == -1)
    assert coloured.sum() > 300
    assert np.all(b[coloured] == -a[coloured])
    # transparency mixes the glass's own shade with what lies behind
    opaque = render(_glass_scene(transparency=0.0)).rgba[..., :3]
    assert np.allclose(opaque[inside], 0.25 * np.array([0.1, 0.8, 0.1]), atol=1e-5)
    half = render(_glass_scene(transparency=0.5)).rgba[..., :3]
    assert np.allclose(half[inside], 0.5 * opaque[inside] + 0.5 * first[inside], atol=1e-5)


def _glass_roof_scene(transparency, roof=True):
    roof_text = "| box((2, 2, 0.2)).translate((0, 0, 1.5)).material(glass)" if roof else ""
    return f"""
        material glass {{ color: (0.1, 0.8, 0.1), transparency: {transparency}, ior: 1.5, specular: 0 }}
        material ground {{ color: (0.8, 0.8, 0.8), specular: 0 }}
        scene plane().material(ground) {roof_text}
        camera {{ position: (0, -5, 1), target: (0, 0, 0), fov: 40 }}
        light directional {{ direction: (0, 0, -1), shadows: hard }}
        render {{ epsilon: 1e-4, dither: 0 }}
    """


@pytest.mark.opencl
def test_hard_shadows_pass_through_transparent_solids():
    """A solid of transparency T passes T of the light to the ground under
    it (straight through, no refraction); an opaque one none."""
    camera = Camera((0, -5, 1), (0, 0, 0), fov=40)
    lit = render(_glass_roof_scene(0.5, roof=False))
    opaque = render(_glass_roof_scene(0.0))
    p = camera.hit_points(lit)
    # ground under the roof, seen directly (the rays pass below the roof)
    under = np.isfinite(lit.depth) & (np.abs(p[..., 0]) < 0.9) & (np.abs(p[..., 1]) < 0.9)
    assert under.sum() > 100
    dark, bright = opaque.rgba[..., 0][under], lit.rgba[..., 0][under]
    assert np.all(bright - dark > 0.3)                       # the opaque roof's shadow
    for transparency in (0.25, 0.5, 1.0):
        seen = render(_glass_roof_scene(transparency)).rgba[..., 0][under]
        assert np.allclose(seen, dark + transparency * (bright - dark), atol=1e-4), transparency


@pytest.mark.opencl
@pytest.mark.parametrize("fractal", ["mandelbulb(power: 8, iterations: 12, bailout: 2)", "julia(iterations: 12)"])
def test_glass_fractals_show_what_lies_behind_them_smoothly(fractal):
    """An escape-time fractal's estimate is about 0 inside, not a depth: a
    ray through it is marched with steps of at least a fraction of the
    scene's bound. Through a glass fractal (transparency 0.8) the red wall
    behind shows on most of it, the image is smoother than the opaque
    fractal's, and other seeds (other dithered hits) change it no more
    than they change the opaque one. (Marched by the depth, the ray came
    out where it went in: noise of the fractal's own shade.)"""
    def renders(transparency):
        scene = fractalc.loads(f"""
            material glass {{ color: (0.9, 0.95, 1.0), specular: 0.5, transparency: {transparency}, ior: 1.3 }}
            material wall {{ color: (1, 0.2, 0.2), specular: 0 }}
            scene {fractal}.material(glass) | box((6, 0.2, 6)).translate((0, 2.5, 0)).material(wall)
            camera {{ position: (0, -3.2, 1.0), target: (0, 0, 0), fov: 40 }}
            light directional {{ direction: (-0.5, 0.4, -1) }}
        """)
        return [scene.render(width=W, height=H, seed=seed) for seed in (0, 1)]
    opaque, glass = renders(0), renders(0.8)
    solid = np.isfinite(opaque[0].depth) & (opaque[0].depth < 4.5)      # the fractal, not the wall
    pairs = solid[:, 1:] & solid[:, :-1]
    assert solid.sum() > 1000

    def roughness(image):
        return np.abs(np.diff(image.rgba[..., :3], axis=1))[pairs].mean()

    def seed_change(images):
        return np.abs(images[0].rgba[..., :3] - images[1].rgba[..., :3])[solid].mean()
    colour = glass[0].rgba[..., :3]
    assert not np.isnan(colour).any()
    assert (colour[..., 0] > 2 * colour[..., 1])[solid].mean() > 0.9
    assert roughness(glass[0]) < 0.5 * roughness(opaque[0])
    assert seed_change(glass) < seed_change(opaque)


@pytest.mark.opencl
@pytest.mark.parametrize("direction", [(0, 0, -1), (0.8, 0, -1), (2, 0, -1), (1, 1.5, -1)])
def test_a_glass_slab_is_counted_once_whatever_the_light_angle(direction):
    """A slab of transparency 0.8 (3 x 3 x 0.2, at height 2) under oblique
    light passes 0.8 of it on every pixel of its shadow: one crossing, one
    factor (stepping out of a solid by a fixed length once re-entered it:
    0.64 and 0.512 in patches)."""
    light = np.array(direction, dtype=np.float64)
    to_light = -light / np.linalg.norm(light)
    # straight down onto the middle of the shadow: every pixel is inside it
    middle = 2 * light[:2] / -light[2]
    camera = Camera((*middle, 1.2), (*middle, 0), up=(0, 1, 0), fov=40)
    image = render(f"""
        material glass {{ color: (0.1, 0.8, 0.1), transparency: 0.8, specular: 0 }}
        material ground {{ color: (0.8, 0.8, 0.8), specular: 0 }}
        scene plane().material(ground) | box((3, 3, 0.2)).translate((0, 0, 2)).material(glass)
        {camera.text()}
        light directional {{ direction: {vec(direction)}, shadows: hard }}
        render {{ epsilon: 1e-4, max_distance: 50 }}
    """)
    diffuse = 0.8 * to_light[2]                       # the ground's unshadowed direct light
    visible = (image.rgba[..., 0].astype(np.float64) - AMBIENT * 0.8) / diffuse
    assert np.abs(visible - 0.8).max() < 1e-4, np.unique(np.round(visible, 3))


# ------------------------------------------------------- effects together

@pytest.mark.opencl
@pytest.mark.parametrize("scene", ["mirror", "glass"])
def test_fog_covers_what_mirrors_and_glass_show(scene):
    """Fog mixes a pixel's colour toward the fog colour by its ray distance t.
    A mirror's colour is its reflection and a clear ball's is what lies
    behind it: they are no nearer than t, so they must be fogged at least as
    much as 1 - exp(-density t) (more, if the bounce's own path counts)."""
    density, fog = 0.3, ", fog: { color: (1, 1, 1), density: 0.3 }"
    if scene == "mirror":
        clear, foggy = render(_mirror_scene(1)), render(_mirror_scene(1, more=fog))
        surface = np.isfinite(foggy.depth) & ~_mirror_prediction()[1]     # the mirror floor
    else:
        clear, foggy = render(_glass_scene()), render(_glass_scene(more=fog))
        surface = _through_the_sphere(1.5)[1]                             # through the ball
    base = clear.rgba[..., :3].astype(np.float64).sum(axis=-1)
    fraction = (foggy.rgba[..., :3].sum(axis=-1) - base) / (3.0 - base)
    expected = 1 - np.exp(-density * foggy.depth.astype(np.float64))
    short = (expected - fraction)[surface]
    assert surface.sum() > 300
    assert short.max() < 1e-3, f"fog missing on {(short > 1e-3).mean():.0%} of the {scene}, up to {short.max():.2f}"


@pytest.mark.opencl
def test_fog_lies_along_the_bounce_too():
    """A mirror's reflection is fogged over both legs: where the bounce hits
    the sphere the fog fraction is 1 - exp(-density (t1 + t2)), t1 to the
    floor and t2 from it to the sphere; where it misses, the pixel is the fog
    colour itself (an infinitely long ray), not the background."""
    density, fog = 0.3, ", fog: { color: (1, 1, 1), density: 0.3 }"
    clear, foggy = render(_mirror_scene(1)), render(_mirror_scene(1, more=fog))
    predicted, direct = _mirror_prediction()
    dirs, origin = MIRROR_CAMERA.rays(), MIRROR_CAMERA.position
    t1 = foggy.depth.astype(np.float64)
    on_floor = origin + np.where(np.isfinite(t1), t1, 0)[..., None] * dirs
    t2 = ray_sphere(on_floor, dirs * np.array([1, 1, -1]), RED_CENTRE, RED_RADIUS)
    base = clear.rgba[..., :3].astype(np.float64).sum(axis=-1)
    fraction = (foggy.rgba[..., :3].sum(axis=-1) - base) / (3.0 - base)
    expected = 1 - np.exp(-density * (t1 + np.where(np.isfinite(t2), t2, 0)))
    assert predicted.sum() > 40
    assert np.abs(fraction - expected)[predicted].max() < 1e-3
    floor = np.isfinite(foggy.depth) & ~direct
    missed = floor & ~np.isfinite(t2)                     # bounces that leave the scene
    assert missed.sum() > 300
    assert np.allclose(foggy.rgba[..., :3][missed], 1.0, atol=1e-5)


# ----------------------------------------------------------------- dithering

DITHER_CAMERA = Camera((0, -4.0, 1.5), (0, 0, 0), fov=40)
DITHER_SCENE = f"""
    scene plane()
    {DITHER_CAMERA.text()}
    {FLAT_LIGHT}
    render {{ ao: 1, ao_method: steps, background: (0, 0, 0) }}
"""


@pytest.mark.opencl
def test_dithering_is_deterministic_per_seed():
    scene = fractalc.loads(textwrap.dedent(DITHER_SCENE))
    a, b = scene.render(width=W, height=H, seed=5), scene.render(width=W, height=H, seed=5)
    other = scene.render(width=W, height=H, seed=6)
    assert np.array_equal(a.rgba, b.rgba) and np.array_equal(a.steps, b.steps)
    assert np.array_equal(a.depth, b.depth)
    hit = np.isfinite(a.depth)
    assert (a.steps != other.steps)[hit].mean() > 0.2
    # without dithering the seed changes nothing (samples 1: no jitter at all)
    plain = [scene.render(width=W, height=H, seed=s, dither=0) for s in (5, 6)]
    assert np.array_equal(plain[0].rgba, plain[1].rgba) and np.array_equal(plain[0].steps, plain[1].steps)


def _banding(steps, height, width):
    """Banding of the steps AOV on the ground: the plane's bands of equal
    step count run across the image, so average each row over the central
    half of the columns and measure (a) the largest jump between
    neighbouring rows and (b) the largest deviation from a smooth (cubic)
    trend. A staircase scores about 1 and 0.5; noise averages out."""
    rows = np.arange(height // 3, height)
    profile = steps[rows][:, width // 4: 3 * width // 4].astype(np.float64).mean(axis=1)
    jump = np.abs(np.diff(profile)).max()
    trend = np.polyval(np.polyfit(rows, profile, 3), rows)
    return jump, np.abs(profile - trend).max()


@pytest.mark.opencl
def test_dithering_reduces_banding():
    width, height = 128, 96
    scene = fractalc.loads(textwrap.dedent(DITHER_SCENE))
    plain = scene.render(width=width, height=height, dither=0)
    assert np.all(plain.steps == np.round(plain.steps))
    plain_jump, plain_band = _banding(plain.steps, height, width)
    assert plain_jump > 0.6 and plain_band > 0.3           # the staircase is there
    for seed in (0, 1, 2):
        dithered = scene.render(width=width, height=height, seed=seed)
        jump, band = _banding(dithered.steps, height, width)
        assert jump < 0.6 * plain_jump, (seed, jump, plain_jump)
        assert band < 0.5 * plain_band, (seed, band, plain_band)
        # the step-count AO colour follows the steps
        hit = np.isfinite(dithered.depth)
        step_ao = 0.8 * AMBIENT * np.clip(1 - dithered.steps / (dithered.steps + 32), 0, 1)
        assert np.allclose(dithered.rgba[..., 0][hit], step_ao[hit], atol=1e-6)


# ------------------------------------------------------------------- epsilon

@pytest.mark.opencl
@pytest.mark.parametrize("epsilon", ["pixel", "1e-3", "0.05"])
def test_hit_threshold_bounds_the_depth_error(epsilon):
    """Sphere tracing stops once the distance falls below the threshold, so
    the depth is short of the true hit by at most threshold / cos(incidence):
    a pixel footprint t * pixel_angle for `epsilon: pixel` (Hart's clarity
    function), the number otherwise."""
    mean_errors = []
    for distance in (3.0, 12.0):
        camera = Camera((0, -distance, 0), (0, 0, 0), fov=40)
        # a second, hidden sphere far behind makes the scene's bounding
        # sphere much larger than the sphere: rays are really marched to it
        scene_text = "scene sphere(1) | sphere(0.1).translate((0, 40, 0))"
        image = render(f"{scene_text}\n{camera.text()}\nrender {{ epsilon: {epsilon}, max_steps: 1000 }}")
        dirs = camera.rays()
        truth = ray_sphere(camera.position, dirs, (0, 0, 0), 1.0)
        both = np.isfinite(truth) & np.isfinite(image.depth)
        on_sphere = camera.position + dirs * np.where(both, truth, 0)[..., None]
        cos = np.abs(np.sum(dirs * on_sphere, axis=-1))           # unit sphere: normal = point
        use = both & (cos > 0.3)
        assert use.sum() > 60
        error = truth[use] - image.depth[use]
        threshold = image.depth[use] * camera.pixel_angle if epsilon == "pixel" else float(epsilon)
        assert error.min() > -2e-5                                  # never past the surface
        assert np.all(error * cos[use] <= threshold * 1.001 + 2e-5)
        assert (error * cos[use] / threshold).max() > 0.5            # and the threshold is what it uses
        mean_errors.append(error.mean())
    ratio = mean_errors[1] / mean_errors[0]
    if epsilon == "pixel":
        assert 2.5 < ratio < 6          # grows with distance (4x farther)
    else:
        assert 0.5 < ratio < 2          # a number: the same at any distance


@pytest.mark.opencl
def test_overrelaxed_marching_finds_the_same_surface_in_fewer_steps():
    """`overrelax: w` steps w * d while successive unbounding spheres overlap
    (Keinert et al. 2014) and falls back to plain steps when they do not:
    the hits stay within the threshold of the surface, the steps drop."""
    camera = Camera((0, -4.0, 1.5), (0, 0, 0), fov=40)
    dirs = camera.rays()
    truth = np.where(dirs[..., 2] < 0, -camera.position[2] / np.minimum(dirs[..., 2], -1e-12), np.inf)
    steps = {}
    for factor in (1.0, 1.2, 1.9):
        image = render(f"scene plane()\n{camera.text()}\nrender {{ epsilon: 1e-4, overrelax: {factor}, dither: 0 }}")
        hit = np.isfinite(image.depth)
        assert hit.sum() > 2500 and np.all(np.isfinite(truth[hit]))
        short = (truth[hit] - image.depth[hit]) * np.abs(dirs[..., 2][hit])   # along the normal
        assert short.min() > -2e-5 and short.max() < 1e-4 + 2e-5
        steps[factor] = image.steps[hit].mean()
    assert steps[1.2] < 0.9 * steps[1.0]
    assert steps[1.9] <= steps[1.0] + 1          # a failed over-step costs at most one step


# ------------------------------------------------------------------- slicing

@pytest.mark.opencl
def test_slice_cut_face_has_the_plane_normal_and_depth():
    camera = Camera((1.0, -4.0, 1.5), (0, 0, 0), fov=40)
    normal, offset = np.array([0.3, -1.0, 0.2]), 0.2
    n = normal / np.linalg.norm(normal)
    sliced = render(f"""
        scene sphere(1)
        {camera.text()}
        render {{ epsilon: 1e-4, slice: {{ normal: {vec(normal)}, offset: {offset} }} }}
    """)
    whole = render(f"scene sphere(1)\n{camera.text()}\nrender {{ epsilon: 1e-4 }}")
    dirs, origin = camera.rays(), camera.position
    assert origin @ n > offset                     # the camera is on the removed side
    t_plane = (offset - origin @ n) / (dirs @ n)
    on_plane = origin + dirs * t_plane[..., None]
    face = (t_plane > 0) & (np.linalg.norm(on_plane, axis=-1) < 0.95)
    assert face.sum() > 300
    assert np.abs(sliced.normal[face] - n).max() < 1e-3
    assert np.abs(sliced.depth[face] - t_plane[face]).max() < 1e-3
    assert np.all(whole.depth[face] < sliced.depth[face] - 0.01)   # the front part is gone
    hit = np.isfinite(sliced.depth)
    kept = camera.hit_points(sliced)[hit] @ n
    assert kept.max() < offset + 1e-3                  # nothing is left in front of the plane


# ------------------------------------------------ kernel source: on and off

PLAIN_SCENE = "scene sphere(1) | plane(offset: -1)"
MATERIAL_SCENE = "scene (sphere(1) | plane(offset: -1)).material(m)"
EFFECTS = {
    # name: (scene, extra declarations, render keys, what its code leaves in the kernel)
    "hard shadows": (PLAIN_SCENE, "light directional { direction: (0, 0, -1), shadows: hard }", {},
                     [r"\bhard_shadow\("]),
    "soft shadows": (PLAIN_SCENE, "light directional { direction: (0, 0, -1), shadows: soft }", {},
                     [r"\bsoft_shadow\("]),
    "ao normal": (PLAIN_SCENE, "", {"ao": "0.5"}, [r"\bambient_occlusion\("]),
    "ao steps": (PLAIN_SCENE, "", {"ao": "0.5", "ao_method": "steps"}, [r"\bstep_occlusion\("]),
    "glow": (PLAIN_SCENE, "", {"glow": "{ strength: 0.5 }"}, [r"\bclosest\b", r"\bGLOW_STRENGTH\b"]),
    "fog": (PLAIN_SCENE, "", {"fog": "{ density: 0.2 }"}, [r"\bFOG_DENSITY\b"]),
    "dither": (PLAIN_SCENE, "", {"dither": "1"}, [r"#define DITHER\b"]),
    "reflections": (MATERIAL_SCENE, "material m { reflectivity: 0.5 }", {"reflections": "2"},
                    [r"\breflected_color\(", r"#define REFLECTIONS\b"]),
    "transparency": (MATERIAL_SCENE, "material m { transparency: 0.5, ior: 1.3 }", {},
                     [r"\btransmitted_color\("]),
    "depth of field": (PLAIN_SCENE, "camera { position: (0, -5, 2), target: (0, 0, 0), aperture: 0.1 }", {},
                       [r"\blens_sample\("]),
    "overrelax": (PLAIN_SCENE, "", {"overrelax": "1.3"}, [r"#define OVERRELAX\b"]),
}
ALL_MARKERS = [(name, marker) for name, entry in EFFECTS.items() for marker in entry[3]]


def _source(scene=PLAIN_SCENE, decls="", keys=None) -> str:
    """The kernel of a scene with dithering and over-relaxation off (both
    are on by default) plus the given declarations and render keys."""
    render_keys = {"dither": "0", "overrelax": "1", **(keys or {})}
    block = "render { " + ", ".join(f"{k}: {v}" for k, v in render_keys.items()) + " }"
    return fractalc.loads("\n".join([scene, decls, block])).kernel_source(lanes=8)


def _distance_function(source: str) -> str:
    return re.search(r"real distance_estimate\(.*?\n}", source, re.S).group(0)


def test_plain_kernel_holds_no_effect_code():
    source = _source()
    for name, marker in ALL_MARKERS:
        assert not re.search(marker, source), (name, marker)
    assert not re.search(r"^#if FEATURE_", source, re.M)
    assert "fmax" not in _distance_function(source)


@pytest.mark.parametrize("effect", sorted(EFFECTS))
def test_each_effect_brings_its_code_and_only_its_code(effect):
    scene, decls, keys, markers = EFFECTS[effect]
    source = _source(scene, decls, keys)
    for marker in markers:
        assert re.search(marker, source), marker
    for name, marker in ALL_MARKERS:
        if name != effect:
            assert not re.search(marker, source), (name, marker)
    assert not re.search(r"^#if FEATURE_", source, re.M)


@pytest.mark.parametrize("scene, decls, keys", [
    (PLAIN_SCENE, "light directional { direction: (0, 0, -1), shadows: none }", {}),
    (PLAIN_SCENE, "", {"ao": "0"}),
    (PLAIN_SCENE, "", {"ao": "0", "ao_method": "steps"}),
    (PLAIN_SCENE, "", {"glow": "{ strength: 0 }"}),
    (PLAIN_SCENE, "", {"fog": "{ density: 0 }"}),
    (PLAIN_SCENE, "", {"dither": "0"}),
    (MATERIAL_SCENE, "material m { reflectivity: 0.5 }", {"reflections": "0"}),
    (MATERIAL_SCENE, "material m { transparency: 0, ior: 1.3 }", {}),
    (PLAIN_SCENE, "camera { position: (0, -5, 2), target: (0, 0, 0), aperture: 0 }", {}),
    (PLAIN_SCENE, "", {"overrelax": "1"}),
], ids=["shadows none", "ao 0", "ao 0 steps", "glow strength 0", "fog density 0", "dither 0",
        "reflections 0", "transparency 0", "aperture 0", "overrelax 1"])
def test_effects_set_to_zero_are_left_out(scene, decls, keys):
    source = _source(scene, decls, keys)
    for name, marker in ALL_MARKERS:
        assert not re.search(marker, source), (name, marker)


def test_slice_adds_the_half_space_to_the_distance():
    plain = _distance_function(_source())
    sliced = _distance_function(_source(keys={"slice": "{ normal: (0, -1, 0), offset: 0.25 }"}))
    assert "fmax" not in plain
    assert "fmax" in sliced and "-0.25f" in sliced


# ------------------------------------------------------------- the examples

def test_every_example_in_the_effects_page_checks():
    page = (REPO / "docs" / "effects.md").read_text()
    blocks = re.findall(r"```frac\n(.*?)```", page, re.S)
    assert len(blocks) >= 10
    for block in blocks:
        fractalc.loads(block, path="docs/effects.md")


def test_glow_and_step_count_ao_march_plainly():
    """Both show the plain march (its closest approach, its step count):
    their kernels do not over-relax, whatever `overrelax` says."""
    assert re.search(r"#define OVERRELAX\b", _source(keys={"overrelax": "1.3"}))
    for keys in ({"glow": "{ strength: 0.5 }"}, {"ao": "0.5", "ao_method": "steps"}):
        assert not re.search(r"#define OVERRELAX\b", _source(keys={**keys, "overrelax": "1.3"})), keys
