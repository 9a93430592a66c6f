"""Denoising a rendered image with Intel Open Image Denoise (OIDN), the
optional extra `denoise` (the pyoidn package): its ray-tracing filter takes
the colour with the image's albedo and normal passes as guides
(docs/looks.md#denoising)."""
from __future__ import annotations

import numpy as np

from .errors import RenderError

MISSING = ("--denoise needs Intel Open Image Denoise, which is not installed: "
           "pip install 'fractalc[denoise]' (the pyoidn package)")


def require_denoiser() -> None:
    """Fail at once, before any rendering, where OIDN is missing."""
    try:
        import pyoidn  # noqa: F401
    except ImportError:
        raise RenderError(MISSING) from None


def denoise_image(image):
    """`image` (an api.Image with the albedo pass) with its colour
    denoised in place: linear HDR colour, guided by the albedo and the
    normals of the pixel-centre rays. The coverage, depth, normals and
    passes stay as rendered."""
    import pyoidn
    colour = np.ascontiguousarray(image.rgba[..., :3], dtype=np.float32)
    albedo = np.ascontiguousarray(np.clip(image.passes["albedo"], 0.0, 1.0), dtype=np.float32)
    normal = np.ascontiguousarray(image.normal, dtype=np.float32)
    try:
        image.rgba[..., :3] = pyoidn.denoise(colour, albedo, normal, hdr=True)
    except RuntimeError as error:
        raise RenderError(f"denoising failed: {error}") from None
    image.metadata["denoised"] = "Intel Open Image Denoise, albedo and normals"
    return image
