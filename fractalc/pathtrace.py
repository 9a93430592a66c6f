"""The path tracer's part of a kernel (render key `integrator: path`,
docs/looks.md#path-tracing): its constants (bounces, the lights as a
table: fractalc/lights.py) and the library file stdlib_cl/pathtrace.cl,
which the emitter places after the engine; and the environment's constants, which both
integrators use: the sky or map, the map's sampling tables, and the
irradiance that lights the direct renderer's surfaces as spherical
harmonics (docs/looks.md#environment)."""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from .lights import LIGHT_KINDS, LIGHT_STRIDE, MAX_INVERSE_SQUARE, MAX_IRRADIANCE, light_layout, lights_table
from .program import CheckedScene
from .resources import resource_dir
from .stdlib import templates

def uses_environment(render) -> bool:
    """Whether the kernel has the template's `environment` (the sky): an
    `environment` block or map, or the path tracer (lit by the background
    without one)."""
    return lights_surfaces(render) or render.integrator == "path"


# An environment map is resampled to MAP_WIDTH x MAP_HEIGHT texels in the
# kernel (with its sampling tables, __constant arrays well under a GPU's
# 64 KB of constant memory).
MAP_WIDTH, MAP_HEIGHT = 64, 32
# The path tracer draws the map's directions in proportion to its
# brightness (importance sampling); False: by solid angle alone.
IMPORTANCE = True
# Light that next-event estimation and the surfaces' lobes both find (area
# lights, an environment map) is weighted between them by the power
# heuristic (multiple importance sampling); False: next-event estimation's
# alone (the path tracer before it, for comparison).
MIS = True


# A map is read MAP_READ_BYTES of float rows at a time and reduced as it
# goes, so that its memory stays that of the table, whatever the map's size
# (benchmarks/environment_map_memory.py); a map wider than MAX_MAP_WIDTH
# would not fit one row in it.
MAP_READ_BYTES = 4 * 2 ** 20
MAX_MAP_WIDTH = MAP_READ_BYTES // 12


def _texel_of(count: int, texels: int) -> np.ndarray:
    """The texel (row or column of the table) each of `count` source rows
    or columns falls in: the one its centre lies in (non-decreasing)."""
    return np.minimum((np.arange(count) + 0.5) * texels // count, texels - 1).astype(int)


@lru_cache(maxsize=8)
def _map_texels(path: str, modified: float) -> np.ndarray:
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(path)
    if image is None:
        raise ValueError(f"cannot read the environment map {path}: {oiio.geterror() or 'unknown format'}")
    try:
        spec = image.spec()
        width, height = spec.width, spec.height
        if spec.nchannels < 3:
            raise ValueError(f"the environment map {path} must have R, G and B channels")
        if width > MAX_MAP_WIDTH:
            raise ValueError(f"the environment map {path} is {width} pixels wide, more than {MAX_MAP_WIDTH}")
        # box filter: each texel the mean of the source pixels whose centres fall in it
        rows, columns = _texel_of(height, MAP_HEIGHT), _texel_of(width, MAP_WIDTH)
        used_columns, column_starts = np.unique(columns, return_index=True)
        counts = (np.bincount(rows, minlength=MAP_HEIGHT)[:, None]
                  * np.bincount(columns, minlength=MAP_WIDTH)[None, :])[..., None]
        sums = np.zeros((MAP_HEIGHT, MAP_WIDTH, 3))
        # a map smaller than the table: the nearest pixel where none falls
        near_rows = np.arange(MAP_HEIGHT) * height // MAP_HEIGHT
        near_columns = np.arange(MAP_WIDTH) * width // MAP_WIDTH
        nearest = np.zeros((MAP_HEIGHT, MAP_WIDTH, 3))
        step = max(1, MAP_READ_BYTES // (width * 12))
        for first in range(0, height, step):
            last = min(first + step, height)
            block = _read_rows(image, spec, first, last, path)
            bad = ~np.isfinite(block)
            if bad.any():
                y, x, _ = np.argwhere(bad)[0]
                shown = ", ".join(f"{v:g}" for v in block[y, x])
                raise ValueError(f"the environment map {path} has a non-finite pixel ({shown}) at x {x}, y {first + y}")
            np.maximum(block, 0.0, out=block)
            band = rows[first:last]
            band_starts = np.flatnonzero(np.diff(band, prepend=-1))
            reduced = np.add.reduceat(np.add.reduceat(block, band_starts, axis=0, dtype=np.float64),
                                      column_starts, axis=1)
            sums[band[band_starts][:, None], used_columns[None, :]] += reduced
            for texel in np.flatnonzero((near_rows >= first) & (near_rows < last)):
                nearest[texel] = block[near_rows[texel] - first, near_columns]
    finally:
        image.close()
    return np.where(counts > 0, sums / np.maximum(counts, 1), nearest)


def _read_rows(image, spec, first: int, last: int, path: str) -> np.ndarray:
    """Rows `first` .. `last` - 1 of the map's first three channels, float32
    (a tiled file's tiles, a scanline file's scanlines)."""
    import OpenImageIO as oiio
    if spec.tile_width:
        top = first - first % spec.tile_height        # whole tiles, then the rows asked for
        bottom = min(spec.height, -(-last // spec.tile_height) * spec.tile_height)
        pixels = image.read_tiles(0, 0, spec.x, spec.x + spec.width, spec.y + top, spec.y + bottom, 0, 1, 0, 3,
                                  oiio.FLOAT)
        pixels = None if pixels is None else pixels.reshape(bottom - top, spec.width, 3)[first - top:last - top]
    else:
        pixels = image.read_scanlines(0, 0, spec.y + first, spec.y + last, 0, 0, 3, oiio.FLOAT)
    if pixels is None:
        raise ValueError(f"cannot read the environment map {path}: {oiio.geterror() or 'a damaged file'}")
    return np.asarray(pixels, dtype=np.float32).reshape(last - first, spec.width, 3)


def environment_map(path: str) -> np.ndarray:
    """The equirectangular map at `path` (any format OpenImageIO reads;
    row 0 looks straight up, +z; columns run from longitude -180 to 180
    degrees about z, 0 along +x) as MAP_HEIGHT x MAP_WIDTH RGB texels."""
    import os
    try:
        modified = os.stat(path).st_mtime
    except OSError as error:
        raise ValueError(f"cannot read the environment map {path}: {error.strerror}") from None
    return _map_texels(path, modified)


def _map_tables(texels: np.ndarray):
    """The map's sampling tables: the cumulative distribution of rows, of
    columns within each row, and each texel's probability density per
    steradian. Texels are drawn in proportion to luminance times solid
    angle (IMPORTANCE), or to solid angle alone."""
    edges = np.cos(np.linspace(0.0, np.pi, MAP_HEIGHT + 1))
    solid_angle = (edges[:-1] - edges[1:])[:, None] * (2 * np.pi / MAP_WIDTH) * np.ones((1, MAP_WIDTH))
    luminance = texels @ np.array([0.2126, 0.7152, 0.0722])
    weight = solid_angle * (luminance if IMPORTANCE else 1.0)
    if weight.sum() <= 0:      # a black map: nothing to draw
        weight = solid_angle
    row_sums = weight.sum(axis=1)
    rows = np.cumsum(row_sums) / row_sums.sum()
    columns = np.cumsum(weight, axis=1) / np.maximum(row_sums, 1e-300)[:, None]
    density = weight / weight.sum() / solid_angle
    return rows, columns, density


def lights_surfaces(render) -> bool:
    """Whether the direct renderer's surfaces are lit by the environment
    (an `environment` block or map) instead of the constant ambient light."""
    return render.environment is not None or render.environment_map is not None


# Directions of a quadrature over the sphere: each texel of the map split
# into QUADRATURE_SPLIT^2 cells of equal solid angle (uniform in z and in
# longitude within the texel), at their centres.
QUADRATURE_SPLIT = 4


def sphere_quadrature():
    """Unit directions (N x 3), their cells' solid angles (N) and the map
    texel each lies in (N: row * MAP_WIDTH + column)."""
    split = (np.arange(QUADRATURE_SPLIT) + 0.5) / QUADRATURE_SPLIT
    top = np.cos(np.arange(MAP_HEIGHT) * np.pi / MAP_HEIGHT)
    bottom = np.cos(np.arange(1, MAP_HEIGHT + 1) * np.pi / MAP_HEIGHT)
    z = top[:, None] - split[None, :] * (top - bottom)[:, None]                       # row, sub-row
    longitude = (np.arange(MAP_WIDTH)[:, None] + split[None, :]) * (2 * np.pi / MAP_WIDTH) - np.pi
    shape = (MAP_HEIGHT, MAP_WIDTH, QUADRATURE_SPLIT, QUADRATURE_SPLIT)   # row, column, sub-row, sub-column
    z = np.broadcast_to(z[:, None, :, None], shape)
    longitude = np.broadcast_to(longitude[None, :, None, :], shape)
    across = np.sqrt(1 - z * z)
    directions = np.stack([across * np.cos(longitude), across * np.sin(longitude), z], axis=-1).reshape(-1, 3)
    solid_angle = np.broadcast_to(((top - bottom) * (2 * np.pi / MAP_WIDTH / QUADRATURE_SPLIT ** 2))
                                  [:, None, None, None], shape).reshape(-1)
    texel = np.broadcast_to((np.arange(MAP_HEIGHT)[:, None] * MAP_WIDTH + np.arange(MAP_WIDTH)[None, :])
                            [:, :, None, None], shape).reshape(-1)
    return directions, solid_angle, texel


def sky_radiance(environment, directions) -> np.ndarray:
    """The sky gradient's radiance (N x 3) along unit `directions` (N x 3)."""
    z = directions[:, 2:3]
    horizon = np.asarray(environment.horizon, dtype=float)
    radiance = (horizon + np.maximum(z, 0) * (np.asarray(environment.zenith) - horizon)
                + np.maximum(-z, 0) * (np.asarray(environment.ground) - horizon))
    return radiance * environment.intensity


def harmonics_basis(n) -> np.ndarray:
    """The 9 real spherical harmonics of order <= 2 at unit vectors n
    (... x 3), without their constant factors: 1, y, z, x, xy, yz,
    3z^2 - 1, xz, x^2 - y^2 (the order of stdlib_cl/shading/environment.cl)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([np.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y], axis=-1)


# Each basis function's squared normalisation (Y = factor * basis), and the
# cosine lobe's convolution weight A_l for its order (Ramamoorthi and
# Hanrahan 2001: pi, 2 pi / 3, pi / 4).
_HARMONIC_FACTORS = np.array([1 / 4] + [3 / 4] * 3 + [15 / 4] * 2 + [5 / 16, 15 / 4, 15 / 16]) / np.pi
_COSINE_LOBE = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)


def environment_radiance(render) -> tuple[np.ndarray, np.ndarray]:
    """The environment's radiance (N x 3) at the quadrature's directions,
    with their solid angles: the map's texel (times the block's
    intensity), or the sky gradient."""
    directions, solid_angle, texel = sphere_quadrature()
    if render.environment_map is not None:
        scale = render.environment.intensity if render.environment is not None else 1.0
        radiance = environment_map(render.environment_map).reshape(-1, 3)[texel] * scale
    else:
        radiance = sky_radiance(render.environment, directions)
    return directions, solid_angle, radiance


def environment_light(render) -> np.ndarray:
    """The environment's irradiance over pi, E(n) / pi, as 9 coefficients
    per colour (9 x 3) of harmonics_basis: the radiance projected on the
    order-2 spherical harmonics by quadrature, each order convolved with
    the cosine lobe (Ramamoorthi and Hanrahan 2001). A white diffuse
    surface facing n shows basis(n) @ coefficients."""
    directions, solid_angle, radiance = environment_radiance(render)
    projections = (harmonics_basis(directions) * solid_angle[:, None]).T @ radiance
    return (_COSINE_LOBE / np.pi * _HARMONIC_FACTORS)[:, None] * projections


def _table(template: str, **values: str) -> str:
    """A table's template of stdlib_cl/scene.cl filled in."""
    return templates("scene.cl")[template].substitute(values)


def environment_constants(render, literal) -> list[str]:
    """The sky's radiance: the environment block's, else the background
    colour everywhere (none with a transparent background); with a map,
    its texels and sampling tables, times the block's intensity."""
    environment = render.environment
    light = []

    def table(name, values):
        return _table("float_table", name=name, values=", ".join(literal(float(v)) for v in np.ravel(values)))
    if lights_surfaces(render):   # the direct renderer's environment light (environment_light)
        light = [table("ENVIRONMENT_LIGHT", environment_light(render))]
    if render.environment_map is not None:
        texels = environment_map(render.environment_map)
        rows, columns, density = _map_tables(texels)
        scale = environment.intensity if environment is not None else 1.0
        return [*light, "#define ENVIRONMENT_MAP 1", f"#define MAP_WIDTH {MAP_WIDTH}", f"#define MAP_HEIGHT {MAP_HEIGHT}",
                table("ENVIRONMENT_TEXELS", np.minimum(texels * scale, MAX_IRRADIANCE)),
                table("ENVIRONMENT_ROWS", rows), table("ENVIRONMENT_COLUMNS", columns),
                table("ENVIRONMENT_DENSITY", density)]
    if environment is None:
        colour = (0.0, 0.0, 0.0) if render.background == "transparent" else render.background
        sky, intensity = {"ZENITH": colour, "HORIZON": colour, "GROUND": colour}, 1.0
    else:
        sky = {"ZENITH": environment.zenith, "HORIZON": environment.horizon, "GROUND": environment.ground}
        intensity = environment.intensity
    return [*light, *(f"#define ENVIRONMENT_{part}_{c} {literal(v * intensity)}"
                      for part, colour in sky.items() for c, v in zip("RGB", colour))]


def source(scene: CheckedScene, literal, transparency: bool) -> str:
    """The path tracer's constants and functions for `scene`, numbers
    written by `literal` (the emitter's float literals); `transparency`:
    whether some material is transparent (the template's FEATURE_TRANSPARENCY)."""
    render = scene.render
    rows = lights_table(scene)
    constants = [*light_layout(),
                 f"#define MAX_INVERSE_SQUARE {literal(MAX_INVERSE_SQUARE)}",
                 f"#define CAMERA_SEES_ENVIRONMENT {int(render.background != 'transparent')}",
                 f"#define PATH_TRANSPARENCY {int(transparency)}",
                 f"#define AREA_LIGHTS {int(any(LIGHT_KINDS[light.kind].area for light in scene.lights))}",
                 f"#define MIS {int(MIS)}",
                 f"#define LIGHT_COUNT {len(rows)}",
                 _table("lights_table", rows="".join(_table("lights_row", values=", ".join(literal(v) for v in row))
                                                     + "\n" for row in rows or [[0.0] * LIGHT_STRIDE]))]
    text = (resource_dir("stdlib_cl") / "pathtrace.cl").read_text()
    return "\n".join(constants) + "\n\n" + text


# Samples per pass: the path tracer renders the image this many samples at
# a time and averages the passes, so that progress shows per pass and no
# launch runs long (GPU watchdogs).
PASS_SAMPLES = 16


def _pass_seed(seed: int, index: int) -> int:
    """A seed per pass, mixed from the image's (a 32-bit hash, so that
    nearby seeds share no pass)."""
    x = (seed * 0x9E3779B1 + index * 0x85EBCA77 + 0x165667B1) & 0xFFFFFFFF
    for shift, factor in ((15, 0x2C1B3C6D), (12, 0x297A2D39)):
        x ^= x >> shift
        x = (x * factor) & 0xFFFFFFFF
    return x ^ (x >> 15)


def pass_frames(frame):
    """`frame` (a run.Frame) as passes of at most PASS_SAMPLES samples,
    each with its own seed."""
    whole, rest = divmod(frame.samples, PASS_SAMPLES)
    counts = [PASS_SAMPLES] * whole + ([rest] if rest else [])
    return [replace(frame, samples=count, seed=_pass_seed(frame.seed, index)) for index, count in enumerate(counts)]


def render_passes(render_frame, frame):
    """The pixels of `frame` as the mean of its passes' colour and coverage,
    each weighted by its samples (summed in double: a pass's colour may
    reach float's largest); the other channels (depth, normals, passes:
    the pixel-centre ray's) are the first pass's. `render_frame(frame)`
    renders one pass into a new array."""
    first, total = None, None
    for part in pass_frames(frame):
        pixels = render_frame(part)
        if first is None:
            first, total = pixels, np.zeros(pixels.shape[:-1] + (4,))
        total += pixels[..., :4] * float(part.samples)
    first[..., :4] = np.minimum(total / frame.samples, np.finfo(np.float32).max)
    return first
