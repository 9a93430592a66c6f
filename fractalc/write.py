"""Stage 7: arrays -> image file (`write`).

EXR: float, linear, channels R G B A Z N.x N.y N.z steps, with metadata.
Anything else (PNG, ...): sRGB 8-bit RGBA. The file appears atomically: it is
written beside its destination under a temporary name, then renamed.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from .errors import RenderError

EXR_CHANNELS = ("R", "G", "B", "A", "Z", "N.x", "N.y", "N.z", "steps")


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def _pixels(planes: dict[str, np.ndarray], exr: bool) -> np.ndarray:
    if exr:
        return np.stack([planes[c] for c in EXR_CHANNELS], axis=-1).astype(np.float32)
    rgb = linear_to_srgb(np.stack([planes[c] for c in "RGB"], axis=-1))
    rgba = np.concatenate([rgb, np.clip(planes["A"], 0, 1)[..., None]], axis=-1)
    return np.round(rgba * 255.0).astype(np.uint8)


def publish(temporary: str, path: str) -> None:
    """Give a finished temporary file the permissions a new file gets
    (mkstemp makes it private) and move it into place atomically."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    os.replace(temporary, path)


def write(path: str, planes: dict[str, np.ndarray], metadata: dict[str, str]) -> None:
    """Write the render's planes to `path` (format from its extension)."""
    import OpenImageIO as oiio
    exr = path.lower().endswith(".exr")
    pixels = _pixels(planes, exr)
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, oiio.FLOAT if exr else oiio.UINT8)
    spec.channelnames = EXR_CHANNELS if exr else ("R", "G", "B", "A")
    spec.alpha_channel = 3
    if exr:
        spec.z_channel = 4
        spec.attribute("compression", "zip")
        for key, value in metadata.items():
            spec.attribute(f"fractalc:{key}", str(value))
    spec.attribute("Software", f"fractalc {metadata.get('version', '')}".strip())
    directory = os.path.dirname(os.path.abspath(path))
    suffix = os.path.splitext(path)[1]
    handle, temporary = tempfile.mkstemp(prefix=".fractalc-", suffix=suffix, dir=directory)
    os.close(handle)
    try:
        output = oiio.ImageOutput.create(temporary)
        if output is None or not output.open(temporary, spec):
            raise RenderError(f"cannot write {path}: {oiio.geterror() or 'unsupported format'}")
        ok = output.write_image(pixels)
        output.close()
        if not ok:
            raise RenderError(f"cannot write {path}: {output.geterror()}")
        publish(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
