"""Float64 numpy reference for the shapes and operations of LANGUAGE.md.

Every function takes points `p` of shape (N, 3) first and returns (N,)
distances. Operations take distance *functions* (p -> (N,)) as arguments;
`shape` binds arguments to make one, so scenes compose like

    shape(translate, shape(sphere, 1.5), (1, 0, 0))     # sphere(1.5).translate((1, 0, 0))

Written from the definitions, not from the kernel, so the two can disagree.
Fractals are not here.
"""

import numpy as np


def shape(fn, *args, **kwargs):
    """The distance function p -> fn(p, *args, **kwargs)."""
    return lambda p: fn(p, *args, **kwargs)


def _vec3(v):
    """A 3-vector from a vector or a number (the number on every axis)."""
    return np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))


def _length(v):
    return np.linalg.norm(v, axis=-1)


# ---------------------------------------------------------------- Primitives

def sphere(p, radius=1.0):
    return _length(p) - radius


def box(p, size=(1.0, 1.0, 1.0)):
    q = np.abs(p) - _vec3(size) / 2
    return _length(np.maximum(q, 0)) + np.minimum(q.max(axis=1), 0)


def plane(p, normal=(0.0, 0.0, 1.0), offset=0.0):
    n = _vec3(normal)
    return p @ (n / np.linalg.norm(n)) - offset


def torus(p, major=1.0, minor=0.25):
    q = np.stack([_length(p[:, :2]) - major, p[:, 2]], axis=1)
    return _length(q) - minor


def cylinder(p, radius=0.5, height=2.0):
    d = np.stack([_length(p[:, :2]) - radius, np.abs(p[:, 2]) - height / 2], axis=1)
    return np.minimum(d.max(axis=1), 0) + _length(np.maximum(d, 0))


def capsule(p, a=(0.0, 0.0, -0.5), b=(0.0, 0.0, 0.5), radius=0.25):
    a, b = _vec3(a), _vec3(b)
    pa, ba = p - a, b - a
    bb = ba @ ba
    h = np.clip(pa @ ba / bb, 0, 1) if bb > 0 else np.zeros(len(p))
    return _length(pa - np.outer(h, ba)) - radius


# -------------------------------------------------------------- Combinations
# Quilez's quadratic polynomial smooth minimum; k = 0 is the plain min/max.

def smin(a, b, k=0.0):
    if k == 0:
        return np.minimum(a, b)
    h = np.maximum(k - np.abs(a - b), 0) / k
    return np.minimum(a, b) - h * h * k / 4


def smax(a, b, k=0.0):
    return -smin(-a, -b, k)


def _fold(combine, p, shapes, k):
    d = shapes[0](p)
    for s in shapes[1:]:
        d = combine(d, s(p), k)
    return d


def union(p, *shapes, smooth=0.0):
    return _fold(smin, p, shapes, smooth)


def intersect(p, *shapes, smooth=0.0):
    return _fold(smax, p, shapes, smooth)


def subtract(p, a, b, smooth=0.0):
    return smax(a(p), -b(p), smooth)


# ---------------------------------------------------------------- Positioning

def translate(p, s, v):
    return s(p - _vec3(v))


def rotation_matrix(axis, degrees):
    """Right-handed rotation by `degrees` about `axis` (Rodrigues)."""
    k = _vec3(axis) / np.linalg.norm(axis)
    t = np.radians(degrees)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.cos(t) * np.eye(3) + np.sin(t) * cross + (1 - np.cos(t)) * np.outer(k, k)


def rotate(p, s, axis, degrees):
    # R^T p for every row p is p @ R.
    return s(p @ rotation_matrix(axis, degrees))


def scale(p, s, f):
    return f * s(p / f)


def round_half_away(x):
    """OpenCL `round`: halves go away from zero (np.round goes to even)."""
    t = np.trunc(x)
    return t + np.where(np.abs(x - t) >= 0.5, np.sign(x), 0)


def repeat(p, s, period):
    c = _vec3(period)
    q = p.copy()
    for axis in np.flatnonzero(c):
        q[:, axis] -= c[axis] * round_half_away(p[:, axis] / c[axis])
    return s(q)


# ---------------------------------------------------------------- Alterations

def round_(p, s, r):
    """`s.round(r)` (named so as not to shadow the builtin)."""
    return s(p) - r


def onion(p, s, t):
    """A shell of thickness t inside the surface of s."""
    return np.abs(s(p) + t / 2) - t / 2


def _lipschitz(g):
    """The step divisor L = (g + sqrt(g^2 + 4)) / 2 of twist and bend."""
    return (g + np.sqrt(g * g + 4)) / 2


def _held(p, warped, axis_point, held_in):
    """A warp's estimate with the sphere that holds the shape (radius
    `held_in` about `axis_point`, a point of the warp's axis, which the warp
    keeps every point's distance to): the sphere's distance where it is at
    least its radius, else the larger of the two (both are lower bounds of
    the distance). Without such a sphere (an unbounded shape), the warped
    estimate alone."""
    if held_in is None:
        return warped
    sphere = _length(p - np.asarray(axis_point, dtype=np.float64)) - held_in
    return np.where(sphere < held_in, np.maximum(warped, sphere), sphere)


def twist(p, s, rate, held_in=None, axis_point=(0.0, 0.0, 0.0)):
    """Twist about z; `held_in`: the radius of a sphere about `axis_point`
    (on the z axis) that holds the shape."""
    x, y, z = p.T
    a = rate * z
    c, n = np.cos(a), np.sin(a)
    q = np.stack([c * x + n * y, -n * x + c * y, z], axis=1)
    return _held(p, s(q) / _lipschitz(abs(rate) * np.hypot(x, y)), axis_point, held_in)


def bend(p, s, rate, held_in=None, axis_point=(0.0, 0.0, 0.0)):
    """Bend in the xz plane; `held_in`: as for twist, about a point of the y axis."""
    x, y, z = p.T
    a = rate * x
    c, n = np.cos(a), np.sin(a)
    q = np.stack([c * x - n * z, y, n * x + c * z], axis=1)
    return _held(p, s(q) / _lipschitz(abs(rate) * np.hypot(x, z)), axis_point, held_in)
