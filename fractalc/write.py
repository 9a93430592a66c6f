"""Stage 7: arrays -> image file (`write`).

EXR: float (or half), linear, channels R G B A Z N.x N.y N.z steps and
the passes asked for (docs/compositing.md), with the OpenEXR standard
`worldToCamera` and `worldToNDC` matrices: the scene's radiance as
rendered, whatever the exposure and tone curve. Anything else (PNG, ...):
the colour scaled by the exposure, through the tone curve, in sRGB RGBA,
8 or 16 bits, straight alpha (docs/looks.md). Both carry the metadata (`fractalc:`
names) where the format has room for it (EXR header, PNG text).

The file appears atomically: it is written beside its destination under a
temporary name, then renamed; the temporary file is removed whatever stops the write (an error, Ctrl-C, or
the CLI's SIGTERM and SIGHUP handlers; a signal that comes while the image writer has the file open is held
until the file is whole, so that no library reports a half-written one). Memory: an EXR is written from the
render's own array (its channels are already interleaved in EXR order),
and a PNG is converted in strips of rows into its integer pixels, so that a
write needs at most a ninth of the float image beyond the render's array.
"""
from __future__ import annotations

import os
import secrets
import signal
import stat
from contextlib import contextmanager

import numpy as np

from .errors import RenderError
from .passes import DEFAULT_CHANNELS

EXR_CHANNELS = DEFAULT_CHANNELS
TEMPORARY_PREFIX = ".fractalc-"
STRIP_ROWS = 64
# the image files `render -o` and the studio write (OpenImageIO, by the extension)
IMAGE_EXTENSIONS = (".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff")
COMPRESSIONS = ("zip", "zips", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab", "rle", "none")
PNG_BITS = (8, 16)
# metadata holding a 4x4 matrix (16 numbers, row-major): OpenEXR standard
# attributes of type m44f in an EXR (OpenImageIO's names on the left)
MATRICES = {"worldtocamera": "worldToCamera", "worldtoNDC": "worldToNDC"}
# channels kept in float by `half`: positions need more than half's 11 bits
FLOAT_ONLY = ("Z", "P.x", "P.y", "P.z")


TONE_CURVES = ("soft", "none", "reinhard", "aces")
DEFAULT_TONE_CURVE = "soft"
# `soft` is the identity up to SOFT_KNEE and a shoulder above it that
# reaches 1 only at infinity: a floor lit a little past 1 (ambient plus a
# light facing it: 1.0 for albedo 0.8) keeps its shading instead of
# clipping to pure white, and everything darker is shown as `none` shows it.
SOFT_KNEE = 0.8


def tone_mapped(linear: np.ndarray, exposure: float = 0.0, curve: str = DEFAULT_TONE_CURVE) -> np.ndarray:
    """Scene-linear colour as display-linear colour in [0, 1]: scaled by
    2^exposure, then through the tone curve (soft: x up to SOFT_KNEE, then
    an exponential shoulder toward 1; none: clipped; reinhard: x / (1 + x)
    per channel; aces: Narkowicz's fit of the ACES film curve)."""
    x = np.maximum(linear * np.float32(2.0 ** exposure), 0.0)
    if curve == "soft":
        room = 1.0 - SOFT_KNEE
        shoulder = SOFT_KNEE + room * -np.expm1(-(x - SOFT_KNEE) / room)
        x = np.where(x > SOFT_KNEE, shoulder, x).astype(x.dtype)
    elif curve == "reinhard":
        x = x / (1.0 + x)
    elif curve == "aces":
        x = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    elif curve != "none":
        raise ValueError(f"tonemap must be one of {', '.join(TONE_CURVES)}, not {curve!r}")
    return np.clip(x, 0.0, 1.0)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def _interleaved(planes: dict[str, np.ndarray]) -> np.ndarray:
    """The planes as one (H, W, channels) float32 array, in the planes'
    order. A render's planes are views of such an array, the kernel's own:
    then it is that array, not a copy."""
    def address(array):
        return array.__array_interface__["data"][0]

    ordered = list(planes.values())
    first = ordered[0]
    itemsize = first.itemsize
    # plane i starts i values after plane 0, with the same strides: the
    # view below covers exactly the planes' own memory
    if all(p.dtype == np.float32 and p.shape == first.shape and p.strides == first.strides
           and address(p) == address(first) + i * itemsize
           for i, p in enumerate(ordered)):
        pixels = np.lib.stride_tricks.as_strided(first, (*first.shape, len(ordered)),
                                                 (*first.strides, itemsize), writeable=False)
        if pixels.flags.c_contiguous:
            return pixels
    return np.stack(ordered, axis=-1).astype(np.float32, copy=False)


def _srgb_rgba(planes: dict[str, np.ndarray], bits: int, transparent: bool,
               exposure: float, curve: str) -> np.ndarray:
    """sRGB RGBA in `bits`-bit integers, converted in strips of rows (the
    float temporaries of the conversion stay a strip's size), the colour
    tone-mapped (`tone_mapped`). Alpha is straight: a transparent render's
    premultiplied colour is divided by its coverage; an opaque render (its
    background fills the misses) is opaque."""
    height, width = planes["A"].shape
    top_value = float(2 ** bits - 1)
    pixels = np.empty((height, width, 4), dtype=np.uint16 if bits == 16 else np.uint8)
    for top in range(0, height, STRIP_ROWS):
        rows = slice(top, top + STRIP_ROWS)
        rgb = np.stack([planes[c][rows] for c in "RGB"], axis=-1)
        alpha = np.clip(planes["A"][rows], 0, 1) if transparent else np.ones_like(planes["A"][rows])
        if transparent:
            covered = alpha > 0
            rgb = np.where(covered[..., None], rgb / np.where(covered, alpha, 1)[..., None], 0)
        rgba = np.concatenate([linear_to_srgb(tone_mapped(rgb, exposure, curve)), alpha[..., None]], axis=-1)
        pixels[rows] = np.round(rgba * top_value)
    return pixels


class WriteError(RenderError):
    """A file could not be written; `cause` is the system's reason."""

    def __init__(self, path: str, cause: str):
        super().__init__(f"cannot write {path}: {cause}")
        self.cause = cause


@contextmanager
def replacing(path: str, publish_when_done: bool = True):
    """A new temporary file beside `path`, for the block to write; when the
    block ends normally it is published onto `path`, and in every case it is
    gone afterwards. OS failures name `path`, never the temporary file."""
    directory = os.path.dirname(os.path.abspath(path))
    # Named before it exists, so that an exception at any point after the
    # file is made (a signal) finds the name to remove; 64 random bits make
    # it no one else's file.
    temporary = os.path.join(directory, f"{TEMPORARY_PREFIX}{secrets.token_hex(8)}{os.path.splitext(path)[1]}")
    try:
        os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        yield temporary
        if publish_when_done:
            publish(temporary, path)
    except OSError as error:
        raise WriteError(path, error.strerror or str(error)) from None
    finally:
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass


def publish(temporary: str, path: str) -> None:
    """Move a finished temporary file onto `path` atomically. A file it
    replaces keeps its permissions; a new one gets those of any new file
    (the umask's), not mkstemp's private ones."""
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(temporary, mode)
    os.replace(temporary, path)


def output_problem(path: str, folders_made: bool = False) -> str | None:
    """Why a file cannot be written at `path`, or None if it can: for
    checking an output before minutes of rendering, not after. With
    `folders_made`, missing folders are fine (they will be made) if the
    nearest one that exists can take them."""
    if os.path.isdir(path):
        return f"'{path}' is a folder"
    folder = os.path.dirname(path) or "."
    if folders_made:
        while not os.path.lexists(folder):
            folder = os.path.dirname(folder) or "."
    if not os.path.exists(folder):
        return f"the folder '{folder}' does not exist"
    if not os.path.isdir(folder):
        return f"'{folder}' is not a folder"
    try:
        with replacing(os.path.join(folder, "probe"), publish_when_done=False):
            pass
    except WriteError as error:
        return f"cannot write in '{folder}': {error.cause}"
    return None


# The signals that stop a command (Ctrl-C, the CLI's SIGTERM and SIGHUP)
_STOPPING_SIGNALS = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}


@contextmanager
def _signals_held():
    """The stopping signals held until the block ends, then delivered: one
    that stopped the image writer between its opening and closing made
    libpng print "No IDATs written into file" after fractalc's own message.
    (Where threads' signal masks are unknown, nothing is held.)"""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, _STOPPING_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def write(path: str, planes: dict[str, np.ndarray], metadata: dict[str, str], half: bool = False,
          compression: str = "zip", bits: int = 8) -> None:
    """Write the render's planes (channel name -> (H, W) array, in channel
    order, R G B A Z first) to `path` (format from its extension). EXR:
    `half` stores all channels but FLOAT_ONLY as half floats, `compression`
    is one of COMPRESSIONS. Other formats: RGBA of `bits` (8 or 16) bits
    where the format has them, the colour tone-mapped as the metadata's
    `render.exposure` and `render.tonemap` say (default: as rendered)."""
    import OpenImageIO as oiio
    if compression not in COMPRESSIONS:
        raise ValueError(f"compression must be one of {', '.join(COMPRESSIONS)}, not {compression!r}")
    if bits not in PNG_BITS:
        raise ValueError(f"bits must be 8 or 16, not {bits!r}")
    exr = path.lower().endswith(".exr")
    height, width = planes["Z"].shape
    names = tuple(planes) if exr else ("R", "G", "B", "A")
    spec = oiio.ImageSpec(width, height, len(names), oiio.FLOAT if exr else
                          (oiio.UINT16 if bits == 16 else oiio.UINT8))
    spec.channelnames = names
    spec.alpha_channel = 3
    matrices = {name: metadata[name] for name in MATRICES.values() if name in metadata}
    if exr:
        spec.z_channel = 4
        spec.attribute("compression", compression)
        if half:
            spec.channelformats = tuple(oiio.FLOAT if n in FLOAT_ONLY else oiio.HALF for n in names)
        for oiio_name, name in MATRICES.items():
            if name in matrices:
                spec.attribute(oiio_name, oiio.TypeMatrix44, tuple(float(x) for x in matrices.pop(name).split()))
    else:
        # the colour is written as `_srgb_rgba` makes it, straight: else
        # OpenImageIO divides it by alpha itself, in float copies of the image
        spec.attribute("oiio:UnassociatedAlpha", 1)
    for key, value in metadata.items():
        if key not in MATRICES.values():
            spec.attribute(f"fractalc:{key}", str(value))
    for name, value in matrices.items():     # PNG: the matrices as text, under their EXR names
        spec.attribute(name, value)
    spec.attribute("Software", f"fractalc {metadata.get('version', '')}".strip())
    transparent = metadata.get("render.background") == "transparent"
    exposure, curve = float(metadata.get("render.exposure", 0.0)), metadata.get("render.tonemap", DEFAULT_TONE_CURVE)
    pixels = _interleaved(planes) if exr else _srgb_rgba(planes, bits, transparent, exposure, curve)
    with replacing(path) as temporary:
        with _signals_held():     # a stop waits for the file to be whole, then removes it
            output = oiio.ImageOutput.create(temporary)
            if output is None or not output.open(temporary, spec):
                raise RenderError(f"cannot write {path}: {oiio.geterror() or 'unsupported format'}")
            try:
                written = output.write_image(pixels)
            finally:
                closed = output.close()
        if not (written and closed):
            raise RenderError(f"cannot write {path}: {output.geterror()}")
