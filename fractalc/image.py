"""A rendered image (`Image`: colour, coverage, AOVs and metadata, saved as
EXR or PNG), made from a render's pixels without copying them, and the
memory an image needs, refused before any work."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .arguments import require_type
from .memory import require_memory
from .passes import DEFAULT_CHANNELS, PASSES
from .write import COMPRESSIONS, write


@dataclass(frozen=True)
class Image:
    """A rendered image: linear colour, coverage alpha and the AOVs of the
    pixel-centre rays (docs/compositing.md)."""
    rgba: np.ndarray        # (H, W, 4) float32, linear; A: the coverage by hits
    depth: np.ndarray       # (H, W) ray distance, +inf where the ray missed
    normal: np.ndarray      # (H, W, 3) world-space normal (0 on misses)
    steps: np.ndarray       # (H, W) march steps
    metadata: dict = field(default_factory=dict)
    passes: dict = field(default_factory=dict)   # pass name (passes.PASSES) -> (H, W, channels) array

    def planes(self) -> dict[str, np.ndarray]:
        """Channel name -> (H, W) array, in the EXR's channel order."""
        planes = {c: self.rgba[..., i] for i, c in enumerate("RGBA")}
        planes["Z"] = self.depth
        planes.update({f"N.{c}": self.normal[..., i] for i, c in enumerate("xyz")})
        planes["steps"] = self.steps
        for name, names in PASSES.items():
            if name in self.passes:
                planes.update({c: self.passes[name][..., i] for i, c in enumerate(names)})
        return planes

    def save(self, path: str | os.PathLike, half: bool = False, compression: str = "zip", bits: int = 8) -> None:
        """Write EXR (linear, all channels, camera matrices, metadata; `half`
        floats, `compression`) or PNG (sRGB, `bits` 8 or 16, straight alpha)."""
        require_type("path", path, (str, os.PathLike), "a file name (str or pathlib.Path)")
        require_type("compression", compression, str, f"a compression's name ({', '.join(COMPRESSIONS)})")
        require_type("bits", bits, int, "8 or 16")
        write(os.fspath(path), self.planes(), self.metadata, half=bool(half), compression=compression, bits=bits)

    def __repr__(self) -> str:
        height, width = self.depth.shape
        return f"<Image {width}x{height}, channels {' '.join(self.planes())}>"

    def _repr_png_(self) -> bytes:
        """Notebooks show the image: its sRGB PNG, as `save` writes it."""
        import tempfile
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "image.png")
            self.save(path)
            with open(path, "rb") as f:
                return f.read()


def image_from_pixels(pixels: np.ndarray, aovs: tuple[str, ...], metadata: dict) -> Image:
    """The Image of a render's (H, W, channels) pixels (passes.DEFAULT_CHANNELS, then
    the `aovs` passes' channels): views of them, no copies."""
    passes, first = {}, len(DEFAULT_CHANNELS)
    for name in aovs:
        count = len(PASSES[name])
        passes[name] = pixels[..., first:first + count]
        first += count
    return Image(pixels[..., 0:4], pixels[..., 4], pixels[..., 5:8], pixels[..., 8], metadata, passes)


# Bytes a pixel takes while rendering, beyond its channels' float32s: the
# path tracer's double sums of colour and coverage, and a pass beside the first
PATH_TRACED_PIXEL_BYTES = 4 * 8


def require_image_memory(width: int, height: int, channel_count: int, path_traced: bool) -> None:
    """Refuse an image that the machine's memory cannot hold (RenderError
    naming its width and height), before any work: its float32 channels,
    twice and its double sums where path-traced (fractalc.pathtrace)."""
    pixel = 4 * channel_count * (2 if path_traced else 1) + (PATH_TRACED_PIXEL_BYTES if path_traced else 0)
    require_memory(width * height * pixel, f"an image of width {width} and height {height} ({channel_count} channels)")
