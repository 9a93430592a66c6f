"""Makes docs/gallery/compositing.png: examples/mandelbulb.frac rendered with a
transparent background over a sky plate (premultiplied "over"), its ao pass and
its material matte. Run from the repository root:
    python docs/gallery/make_compositing.py
"""
import numpy as np
import OpenImageIO as oiio

import fractalc

scene = fractalc.load("examples/mandelbulb.frac")
image = scene.render(width=320, height=240, samples=4, background="transparent", aovs=("ao", "material"))
rgba = image.rgba
h, w = rgba.shape[:2]
plate = np.zeros((h, w, 3), np.float32)
t = np.linspace(0, 1, h)[:, None]
plate[...] = (0.55 + 0.35 * t)[..., None] * np.array([0.35, 0.55, 0.9], np.float32)   # a sky plate
over = rgba[..., :3] + (1 - rgba[..., 3:4]) * plate            # premultiplied "over"
ao = np.repeat(image.passes["ao"][..., :1], 3, axis=2)
material = image.passes["material"][..., 0]
ids = np.where(material[..., None] >= 0, np.array([0.95, 0.75, 0.3], np.float32), 0.0) * rgba[..., 3:4]
strip = np.concatenate([over, ao, ids], axis=1)
srgb = np.where(strip <= 0.0031308, 12.92 * strip, 1.055 * np.clip(strip, 0, 1) ** (1 / 2.4) - 0.055)
out = oiio.ImageBuf(oiio.ImageSpec(strip.shape[1], h, 3, oiio.UINT8))
out.set_pixels(oiio.ROI(), np.ascontiguousarray(np.round(np.clip(srgb, 0, 1) * 255).astype(np.uint8)))
out.write("docs/gallery/compositing.png")
print("ok")
