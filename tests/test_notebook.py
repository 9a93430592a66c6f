"""In a notebook: images show themselves, scenes and images have short
reprs, and `fractalc.Camera` is checked as a file's camera block is."""
import numpy as np
import OpenImageIO as oiio
import pytest

import fractalc

SCENE = """param r = 1 in [0.5, 2]
scene sphere(r)
camera { position: (0, -4, 0), target: (0, 0, 0), fov: 40 }
render { width: 16, height: 12 }
"""


@pytest.fixture(scope="module")
def scene():
    return fractalc.loads(SCENE, path="ball.frac")


@pytest.fixture(scope="module")
def image(scene):
    return scene.render()


@pytest.mark.opencl
def test_image_shows_itself_as_its_srgb_png(image, tmp_path):
    data = image._repr_png_()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    shown = tmp_path / "shown.png"
    shown.write_bytes(data)
    saved = tmp_path / "saved.png"
    image.save(str(saved))
    pixels = [np.asarray(oiio.ImageBuf(str(p)).get_pixels(oiio.UINT8)) for p in (shown, saved)]
    assert pixels[0].shape == (12, 16, 4)
    assert np.array_equal(pixels[0], pixels[1])
    assert pixels[0][6, 8, :3].max() > 0    # the ball, lit, in the middle


@pytest.mark.opencl
def test_image_repr_is_short(image):
    text = repr(image)
    assert text.startswith("<Image 16x12, channels R G B A Z N.x N.y N.z steps")
    assert len(text) < 200 and "array" not in text


def test_scene_repr_names_file_params_precision_and_device(scene, monkeypatch):
    monkeypatch.delenv("FRACTALC_DEVICE", raising=False)
    assert repr(scene) == "<Scene ball.frac: params r=1; precision float; device default>"
    other = fractalc.loads(SCENE, path="ball.frac", params={"r": 1.5}, precision="double", device="cpu")
    assert repr(other) == "<Scene ball.frac: params r=1.5; precision double; device cpu>"


@pytest.mark.opencl
def test_public_camera_renders_its_view(scene):
    front = scene.render(camera=fractalc.Camera(position=(0, -4, 0), target=(0, 0, 0), fov=40))
    side = scene.render(camera=fractalc.Camera(position=(3, -4, 0), target=(3, 0, 0), fov=40))
    assert np.array_equal(front.rgba, scene.render().rgba)   # the file's camera, given explicitly
    assert np.isfinite(front.depth[6, 8]) and not np.isfinite(side.depth[6, 8])


def test_camera_values_become_floats():
    camera = fractalc.Camera(position=[1, 2, 3], target=(0, 0, 0), fov=30)
    assert camera.position == (1.0, 2.0, 3.0) and isinstance(camera.fov, float)


@pytest.mark.parametrize("keys, message", [
    ({"fov": 200}, "'fov' of 'camera' must be less than 180"),
    ({"fov": 0}, "'fov' of 'camera' must be greater than 0"),
    ({"position": (1, 2)}, "'position' must have 3 components"),
    ({"target": "origin"}, "'target' must be a 3-vector"),
    ({"up": (0, 0, 0)}, "'up' of 'camera' must not be zero"),
    ({"aperture": -1}, "'aperture' of 'camera' must be at least 0"),
    ({"focus": 0}, "'focus' of 'camera' must be greater than 0"),
    ({"fov": float("nan")}, "'fov' must be finite"),
    ({"position": (1, 1, 1), "target": (1, 1, 1)}, "'target' is its 'position'"),
    ({"position": (0, 0, 5), "target": (0, 0, 0), "up": (0, 0, 2)}, "'up' is parallel"),
])
def test_camera_mistakes_name_the_key(keys, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        fractalc.Camera(**keys)


def test_camera_looking_along_the_default_up_takes_y_up():
    # as for a camera block without 'up'
    assert fractalc.Camera(position=(0, 0, 5), target=(0, 0, 0)).up == (0.0, 1.0, 0.0)
