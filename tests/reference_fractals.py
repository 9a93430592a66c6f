"""Float64 numpy reference for the fractals of LANGUAGE.md ("Fractals: the
exact formulas").

Every distance estimate takes points `p` of shape (N, 3) first and returns
(N,) values, with the arguments of the language call (c as a 4-tuple) after
it. They follow the contract literally (no overflow guards): use them where
float64 does not overflow. For menger and sierpinski, `menger_distance` and
`sierpinski_distance` are the exact (unsigned, 0 inside) distances to the
solids, as the minimum over their 20^N boxes / 4^N tetrahedra.

Written from the contract, not from the OpenCL library, so the two can
disagree.
"""

from functools import lru_cache
from itertools import product

import numpy as np


def _length(v):
    return np.linalg.norm(v, axis=-1)


# ---------------------------------------------------------------- Escape-time fractals

def mandelbulb(p, power=8.0, iterations=12, bailout=2.0):
    p = np.asarray(p, dtype=np.float64)
    z, dr = p.copy(), np.ones(len(p))
    active = np.ones(len(p), dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for _ in range(iterations):
            r = _length(z)
            active &= r <= bailout
            if not active.any():
                break
            za, ra, dra = z[active], r[active], dr[active]
            cos_theta = np.where(ra > 0, np.clip(za[:, 2] / ra, -1, 1), 1.0)
            theta = np.arccos(cos_theta) * power
            phi = np.arctan2(za[:, 1], za[:, 0]) * power
            dr[active] = power * ra ** (power - 1) * dra + 1
            direction = np.stack([np.sin(theta) * np.cos(phi), np.sin(phi) * np.sin(theta),
                                  np.cos(theta)], axis=1)
            z[active] = ra[:, None] ** power * direction + p[active]
        r = _length(z)
        return np.where(r > 0, 0.5 * np.log(r) * r / dr, 0.0)


def julia(p, c=(-0.2, 0.6, 0.2, 0.0), slice=0.0, iterations=12, bailout=4.0):
    p = np.asarray(p, dtype=np.float64)
    q = np.concatenate([p, np.full((len(p), 1), float(slice))], axis=1)   # (real, i, j, k)
    c = np.asarray(c, dtype=np.float64)
    dr = np.ones(len(p))
    active = np.ones(len(p), dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for _ in range(iterations):
            r = _length(q)
            active &= r <= bailout
            if not active.any():
                break
            qa = q[active]
            dr[active] = 2 * r[active] * dr[active]
            square = np.concatenate([qa[:, :1] ** 2 - (qa[:, 1:] ** 2).sum(axis=1, keepdims=True),
                                     2 * qa[:, :1] * qa[:, 1:]], axis=1)
            q[active] = square + c
        r = _length(q)
        return np.where((r > 0) & (dr != 0), 0.5 * np.log(r) * r / dr, 0.0)


def mandelbox(p, scale=2.0, min_radius=0.5, fixed_radius=1.0, fold_limit=1.0, iterations=12):
    z, dr = mandelbox_orbit(p, scale, min_radius, fixed_radius, fold_limit, iterations)
    return _length(z) / np.abs(dr)


def mandelbox_orbit(p, scale=2.0, min_radius=0.5, fixed_radius=1.0, fold_limit=1.0, iterations=12):
    """The final z (N, 3) and dr (N,) of the Mandelbox iteration."""
    p = np.asarray(p, dtype=np.float64)
    z, dr = p.copy(), np.ones(len(p))
    min2, fixed2 = min_radius ** 2, fixed_radius ** 2
    with np.errstate(divide="ignore"):
        for _ in range(iterations):
            z = np.clip(z, -fold_limit, fold_limit) * 2 - z
            r2 = (z * z).sum(axis=1)
            factor = np.where(r2 < min2, fixed2 / min2, np.where(r2 < fixed2, fixed2 / r2, 1.0))
            z = z * factor[:, None]
            dr = dr * factor
            z = scale * z + p
            dr = dr * abs(scale) + 1
    return z, dr


# ---------------------------------------------------------------- Exact solids

def box_distance(p, centres, half):
    """(N, M) exact unsigned distances from points to axis-aligned boxes."""
    q = np.abs(p[:, None, :] - centres[None, :, :]) - half
    return np.sqrt((np.maximum(q, 0) ** 2).sum(axis=2))


# The 20 kept sub-cubes of a cell, as offsets of their centres in units of
# their edge: at most one coordinate 0 (the others are the removed cross).
MENGER_OFFSETS = np.array([o for o in product((-1, 0, 1), repeat=3) if sum(x == 0 for x in o) <= 1],
                          dtype=np.float64)


@lru_cache(maxsize=None)
def menger_cubes(level):
    """Centres (M, 3) and half edge of the 20^level cubes of the sponge."""
    centres, half = np.zeros((1, 3)), 1.0
    for _ in range(level):
        half /= 3
        centres = (centres[:, None, :] + 2 * half * MENGER_OFFSETS[None, :, :]).reshape(-1, 3)
    return centres, half


def menger_distance(p, level):
    centres, half = menger_cubes(level)
    return _chunked_min(p, lambda chunk: box_distance(chunk, centres, half))


TETRAHEDRON = np.array([(1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1)], dtype=np.float64)


@lru_cache(maxsize=None)
def sierpinski_tetrahedra(level):
    """(M, 4, 3): the vertices of the 4^level tetrahedra of the solid."""
    tetrahedra = TETRAHEDRON[None]
    for _ in range(level):
        # each tetrahedron -> its four halves, each scaled by 1/2 about one vertex
        # [m, i, j] = (vertex j + vertex i) / 2 of tetrahedron m
        tetrahedra = ((tetrahedra[:, None, :, :] + tetrahedra[:, :, None, :]) / 2).reshape(-1, 4, 3)
    return tetrahedra


def segment_distance(p, a, b):
    """(N, M) distances from points (N, 3) to segments a, b (M, 3)."""
    ab = b - a
    ap = p[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(axis=2) / (ab * ab).sum(axis=1)[None], 0, 1)
    return _length(ap - t[..., None] * ab[None])


def triangle_distance(p, a, b, c):
    """(N, M) exact distances from points to triangles (a, b, c), each (M, 3)."""
    normal = np.cross(b - a, c - a)
    normal /= _length(normal)[:, None]
    ap = p[:, None, :] - a[None]
    height = (ap * normal[None]).sum(axis=2)
    projected = p[:, None, :] - height[..., None] * normal[None]
    # inside the triangle: the projection is on the inner side of every edge
    inside = np.ones(height.shape, dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, projected - u[None]) * normal[None]).sum(axis=2) >= 0
    edges = np.minimum(np.minimum(segment_distance(p, a, b), segment_distance(p, b, c)),
                       segment_distance(p, c, a))
    return np.where(inside, np.abs(height), edges)


def tetrahedron_distance(p, tetrahedra):
    """(N, M) exact unsigned distances (0 inside) to tetrahedra (M, 4, 3)."""
    a, b, c, d = (tetrahedra[:, i] for i in range(4))
    faces = ((a, b, c, d), (a, b, d, c), (a, c, d, b), (b, c, d, a))
    inside = np.ones((len(p), len(tetrahedra)), dtype=bool)
    nearest = np.full(inside.shape, np.inf)
    for u, v, w, opposite in faces:
        normal = np.cross(v - u, w - u)
        # the side of the face's plane the opposite vertex is on is inside
        sign = np.sign(((opposite - u) * normal).sum(axis=1))
        inside &= (((p[:, None, :] - u[None]) * normal[None]).sum(axis=2) * sign[None]) >= 0
        nearest = np.minimum(nearest, triangle_distance(p, u, v, w))
    return np.where(inside, 0.0, nearest)


def sierpinski_distance(p, level):
    tetrahedra = sierpinski_tetrahedra(level)
    return _chunked_min(p, lambda chunk: tetrahedron_distance(chunk, tetrahedra))


def _chunked_min(p, distances, budget=4_000_000):
    """min over axis 1 of `distances(chunk)`, in chunks of about `budget` pairs."""
    p = np.asarray(p, dtype=np.float64)
    columns = distances(p[:1]).shape[1]
    step = max(1, budget // columns)
    return np.concatenate([distances(p[i:i + step]).min(axis=1) for i in range(0, len(p), step)])
