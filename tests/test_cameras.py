"""Cameras (docs/looks.md#cameras): pinhole, fisheye and equirectangular
projections, side-by-side and top-bottom stereo (omni-directional with the
equirectangular projection). A small sphere moved by params (no rebuild)
lands where a projection written here independently of the kernel puts its
centre: the coverage-weighted centroid of its pixels. Renders are 64 x 48
or 64 x 32."""

import math

import numpy as np
import pytest

import fractalc
from fractalc import run
from fractalc.api import Camera

SCENE = """
param x = 0
param y = 0
param z = 0
param r = 0.1
scene sphere(r).translate((x, y, z))
camera { position: (0.4, -3, 0.7), target: (0, 0, 0.2) }
render { epsilon: 1e-5, dither: 0, samples: 16, background: transparent }
"""


def camera_frame(camera):
    block = np.array(run.camera_block(camera))
    return block[0:3], block[6:9], block[9:12], block[3:6]   # position, right, up', forward


def projected(camera, point, width, height):
    """Where `point`'s direction from the eye lands, in pixels from the
    top-left corner (x right, y down), by inverting each projection."""
    position, right, up, forward = camera_frame(camera)
    eye_width, eye_height, shift = width, height, (0.0, 0.0)
    separation = camera.eye_separation
    eye = 0.0
    if camera.stereo != "none":
        eye = camera.eye                       # -1 left, 1 right (set by the test)
        if camera.stereo == "side_by_side":
            eye_width, shift = width / 2, ((eye + 1) / 2 * width / 2, 0.0)
        else:
            eye_height, shift = height / 2, (0.0, (eye + 1) / 2 * height / 2)
    p = np.asarray(point, dtype=float) - position
    x, y, z = p @ right, p @ up, p @ forward
    if camera.projection == "pinhole":
        if eye:
            # the eye's ray through the point meets the plane in focus where
            # the camera centre's ray of the same pixel does
            e = eye * separation / 2
            focus = camera.focus if camera.focus is not None else np.linalg.norm(
                np.subtract(camera.target, camera.position))
            x, y, z = e + (x - e) * focus / z, y * focus / z, focus
        tan_half = math.tan(math.radians(camera.fov) / 2)
        a, b = x / z / tan_half, y / z / tan_half
    elif camera.projection == "fisheye":
        x = x - eye * separation / 2              # parallel eyes
        theta = math.acos(z / math.sqrt(x * x + y * y + z * z))
        rho = theta / math.radians(camera.fisheye_fov / 2)
        a, b = rho * x / math.hypot(x, y), rho * y / math.hypot(x, y)
    else:
        # omni-directional stereo: the ray from the eye circle (radius r),
        # across its column's direction, that passes through the point
        horizontal, r = math.hypot(x, z), eye * separation / 2
        longitude = math.atan2(x, z) - math.asin(r / horizontal)
        latitude = math.atan2(y, math.sqrt(horizontal ** 2 - r ** 2))
        a = longitude / math.pi * eye_width / eye_height
        b = latitude / (math.pi / 2)
    return (shift[0] + (a * eye_height + eye_width) / 2, shift[1] + (eye_height - b * eye_height) / 2)


def pixel_angle(camera, width, height):
    if camera.projection == "pinhole":
        return 2 * math.tan(math.radians(camera.fov) / 2) / height
    if camera.projection == "fisheye":
        return math.radians(camera.fisheye_fov) / height
    return 2 * math.pi / width


def centroid(scene, camera, point, width, height, region=None):
    """The sphere at `point`, about 2 pixels in radius: its centroid."""
    distance = np.linalg.norm(np.subtract(point, camera.position))
    radius = 2 * pixel_angle(camera, width, height) * distance
    scene.set_params({**dict(zip("xyz", point)), "r": radius})
    alpha = scene.render(camera=camera, width=width, height=height).rgba[..., 3].astype(float)
    if region is not None:
        alpha = np.where(region, alpha, 0.0)
    rows, columns = np.indices(alpha.shape) + 0.5
    assert alpha.sum() > 1, f"the sphere at {point} is not in the picture"
    return (columns * alpha).sum() / alpha.sum(), (rows * alpha).sum() / alpha.sum()


class EyeCamera(Camera):
    """A camera that also says which eye the test projects for."""
    eye: float = 0.0


def eye_camera(eye, **keys):
    camera = Camera(position=(0.4, -3, 0.7), target=(0, 0, 0.2), **keys)
    object.__setattr__(camera, "eye", eye)
    return camera


POINTS = [(0, 0, 0.2), (0.6, 0.3, 0.5), (-0.7, -0.4, -0.2), (0.3, 0.8, 1.0)]


@pytest.mark.parametrize("keys", [{"projection": "pinhole", "fov": 50},
                                  {"projection": "fisheye", "fisheye_fov": 180},
                                  {"projection": "fisheye", "fisheye_fov": 300},
                                  {"projection": "equirectangular"}])
@pytest.mark.opencl
def test_points_land_on_their_projected_pixels(keys):
    scene = fractalc.loads(SCENE)
    width, height = (64, 32) if keys["projection"] == "equirectangular" else (64, 48)
    camera = eye_camera(0.0, **keys)
    points = POINTS + ([(-1.5, -3.5, 0.9), (2.0, -4.0, 0.2)] if keys.get("fisheye_fov") == 300 else [])
    if keys["projection"] == "equirectangular":   # all around: beside and behind the camera
        points += [(2.4, -3.2, 0.4), (-1.0, -4.5, 1.1), (0.2, -4.2, 0.6)]
    for point in points:
        expected = projected(camera, point, width, height)
        found = centroid(scene, camera, point, width, height)
        assert np.hypot(found[0] - expected[0], found[1] - expected[1]) < 0.15, (point, found, expected)


@pytest.mark.parametrize("projection, stereo", [("pinhole", "side_by_side"), ("pinhole", "top_bottom"),
                                                ("fisheye", "side_by_side"), ("equirectangular", "top_bottom")])
@pytest.mark.opencl
def test_each_eye_sees_from_its_own_place(projection, stereo):
    scene = fractalc.loads(SCENE)
    width, height = (64, 64) if stereo == "top_bottom" else (96, 32)
    rows, columns = np.indices((height, width))
    halves = [columns < width // 2, columns >= width // 2] if stereo == "side_by_side" else \
             [rows < height // 2, rows >= height // 2]
    disparity = {}
    for point in [(0, 0, 0.2), (0.3, -1.5, 0.5), (-0.2, -1.9, 0.6), (0.2, 1.5, 0)]:
        found = []
        for eye, half in zip((-1.0, 1.0), halves):
            camera = eye_camera(eye, projection=projection, stereo=stereo, eye_separation=0.4, fov=60)
            expected = projected(camera, point, width, height)
            found.append(centroid(scene, camera, point, width, height, half))
            assert np.hypot(found[-1][0] - expected[0], found[-1][1] - expected[1]) < 0.15, (eye, point)
        disparity[point] = found[0][0] - (found[1][0] - width / 2)
    if stereo == "side_by_side" and projection == "pinhole":
        # no parallax on the plane in focus (through the target); a nearer
        # point is seen further right by the left eye, a farther one left
        assert abs(disparity[(0, 0, 0.2)]) < 0.05
        assert disparity[(0.3, -1.5, 0.5)] > 2 and disparity[(0.2, 1.5, 0)] < -0.5


@pytest.mark.opencl
def test_the_360_image_wraps_seamlessly():
    text = """
    scene sphere(0.4).translate((1, 2, 0.2)) | box(0.5).translate((-1.5, -1, 0)) | plane(offset: -0.6)
        | torus(0.6, 0.15).translate((0.5, -2, 0.8))
    light directional { direction: (-1, 0.5, -2), shadows: soft }
    render { width: 64, height: 32, dither: 0 }
    """
    scene = fractalc.loads(text)
    ahead = Camera(position=(0, 0, 0.3), target=(0, 1, 0.3), projection="equirectangular")
    behind = Camera(position=(0, 0, 0.3), target=(0, -1, 0.3), projection="equirectangular")
    a = scene.render(camera=ahead).rgba[..., :3]
    b = scene.render(camera=behind).rgba[..., :3]
    # turned half round, the image is the same, rolled by half its width:
    # a's edges meet in b's middle
    assert np.abs(np.roll(a, 32, axis=1) - b).max() < 2e-3
    seam = np.abs(a[:, 0] - a[:, -1]).mean()
    inside = np.abs(np.diff(a, axis=1)).mean(axis=(0, 2))
    assert seam <= np.percentile(inside, 90), (seam, inside)
    assert np.abs(b[:, 31] - b[:, 32]).mean() == pytest.approx(seam, abs=2e-3)


@pytest.mark.opencl
def test_fisheye_pixels_past_360_degrees_are_empty():
    scene = fractalc.loads("scene plane(offset: -1) | sphere(30).onion(0.1)\nrender { width: 64, height: 32 }")
    image = scene.render(camera=Camera(position=(0, 0, 0), target=(0, 1, 0), projection="fisheye",
                                       fisheye_fov=360))
    rows, columns = np.indices((32, 64)) + 0.5
    rho = np.hypot((2 * columns - 64) / 32, (32 - 2 * rows) / 32)
    assert np.all(image.rgba[..., 3][rho > 1.02] == 0)     # inside a sphere, every ray hits
    assert np.all(image.rgba[..., 3][rho < 0.98] == 1)


@pytest.mark.opencl
def test_animation_keeps_the_projection():
    from fractalc.animate import render_frame
    scene = fractalc.loads("""
    scene sphere(0.5) | plane(offset: -1)
    camera { projection: fisheye, fisheye_fov: 200, stereo: side_by_side }
    path { 0: { position: (0, -4, 1) }, 1: { position: (3, -3, 2) } }
    render { width: 32, height: 16 }
    """)
    frame = render_frame(scene, scene.checked.path, 0.5, 0, {})
    from fractalc.paths import camera_at
    camera = camera_at(scene.checked.path, scene.checked.camera, 0.5)
    assert (camera.projection, camera.fisheye_fov, camera.stereo) == ("fisheye", 200, "side_by_side")
    assert np.array_equal(frame.rgba, scene.render(camera=camera).rgba)
    pinhole = scene.render(camera=Camera(position=camera.position, target=camera.target))
    assert not np.array_equal(frame.rgba, pinhole.rgba)


@pytest.mark.parametrize("entry, message", [
    ("projection: orthographic", "'projection' must be 'pinhole' or 'fisheye' or 'equirectangular'"),
    ("fisheye_fov: 400", "'fisheye_fov' of 'camera' must be at most 360, not 400"),
    ("stereo: anaglyph", "'stereo' must be 'none' or 'side_by_side' or 'top_bottom'"),
    ("eye_separation: -1", "'eye_separation' of 'camera' must be at least 0, not -1"),
])
def test_bad_camera_keys_are_errors_at_the_value(entry, message):
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads(f"scene sphere()\ncamera {{ {entry} }}\n")
    assert message in str(caught.value) and ":2:" in str(caught.value)


def test_a_path_keyframe_does_not_take_the_projection():
    with pytest.raises(fractalc.SceneError) as caught:
        fractalc.loads("scene sphere()\npath { 0: { position: (0, -4, 0), projection: fisheye },"
                       "  1: { position: (0, -5, 0) } }\n")
    assert "'path' has no key 'projection'" in str(caught.value)


@pytest.mark.opencl
@pytest.mark.parametrize("build", [{"lanes": 1}, {"precision": "double"}])
def test_every_camera_renders_alike_on_one_lane_and_in_double(build):
    # a hit threshold of 1e-4, not the scene's 1e-5: normals by differences
    # that small take the float estimate's last bits (a thousandth of the
    # colour, which Intel's runtime rounds differently in a kernel of 16
    # lanes and one of 1: 1.6-2.8e-3 over four nearby params), where this
    # test compares the cameras' rays (within 2.5e-4 with 1e-4)
    text = (SCENE.replace("samples: 16", "samples: 4").replace("epsilon: 1e-5", "epsilon: 1e-4")
            + "\nlight directional { direction: (-1, 1, -1) }")
    cameras = [eye_camera(0.0, projection="fisheye", fisheye_fov=250, stereo="side_by_side", eye_separation=0.3),
               eye_camera(0.0, projection="equirectangular", stereo="top_bottom", eye_separation=0.3),
               eye_camera(0.0, fov=70, stereo="side_by_side", eye_separation=0.3, aperture=0.1)]
    for camera in cameras:
        images = []
        for scene in (fractalc.loads(text), fractalc.loads(text, **build)):
            scene.set_params({"x": 0.3, "y": -1.0, "z": 0.4, "r": 0.6})
            images.append(scene.render(camera=camera, width=48, height=24).rgba)
        assert images[0][..., 3].sum() > 4
        assert np.abs(images[0] - images[1]).max() < 1e-3, camera
