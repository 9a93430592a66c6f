"""Float64 numpy references of the library's formulas (stdlib_frac/formulas.frac),
written from their sources, not from fractalc: each formula's step on (N, 3)
arrays, the standard running derivative where the literature gives one
(Syntopia, "Distance Estimated 3D Fractals", parts III-VI: the Amazing Box's
dr -> |s| m dr + 1, a KIFS's dr -> s dr, q^2 + c's dr -> 2 |q| dr + 1, the
bulb's dr -> n r^(n-1) dr + 1) and otherwise a finite-difference Jacobian of
the whole orbit.

An orbit runs like a renderer's loop: a ray stops once |z| passes the
bailout, and a step whose z is not finite or longer than 1e18 is not taken
(the ray stops with its last state)."""
from __future__ import annotations

import numpy as np

OVERFLOW = 1e18
DR_CAP = 1e30
PHI = (1 + 5 ** 0.5) / 2


def _norm(v):
    return np.sqrt(np.sum(v * v, axis=-1))


def rotation(axis, degrees):
    """The right-handed rotation matrix about `axis` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.radians(degrees)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) * np.cos(a) + np.sin(a) * cross + (1 - np.cos(a)) * np.outer(k, k)


def _turn(z, axis, degrees):
    return z @ rotation(axis, degrees).T


def _sphere_factor(z, min_radius, fixed_radius):
    r2 = np.maximum(np.sum(z * z, axis=-1), 1e-30)
    return np.clip(fixed_radius ** 2 / r2, 1.0, fixed_radius ** 2 / min_radius ** 2)


def _mirror_below(z, normal, offset=0.0):
    """Reflect z in the plane n.z = offset where n.z < offset."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    side = np.minimum(z @ n - offset, 0.0)
    return z - 2 * side[:, None] * n


# ---- steps: (z, c, state, params) -> (z, state, factor) ------------------------
# factor: how much the step scales lengths (None: not a similarity); state:
# the formula's carried values.

def amazing_box(z, c, state, scale=2.0, fold=1.0, min_radius=0.5, fixed_radius=1.0):
    z = np.where(z > fold, 2 * fold - z, np.where(z < -fold, -2 * fold - z, z))
    m = _sphere_factor(z, min_radius, fixed_radius)
    return scale * m[:, None] * z + c, state, abs(scale) * m


def amazing_surf(z, c, state, scale=1.8, fold=1.0, min_radius=0.5, axis=(0, 1, 0), angle=0.0):
    z = z.copy()
    xy = z[:, :2]
    z[:, :2] = np.where(xy > fold, 2 * fold - xy, np.where(xy < -fold, -2 * fold - xy, xy))
    m = _sphere_factor(z, min_radius, 1.0)
    return _turn(scale * m[:, None] * z + c, axis, angle), state, abs(scale) * m


def abox_mod_kali(z, c, state, scale=1.5, corner=(0.5, 0.5, 0.5), min_radius=0.7746, axis=(1, 0, 0), angle=0.0):
    z = np.asarray(corner) - np.abs(_turn(z, axis, angle))
    m = _sphere_factor(z, min_radius, 1.0)
    return scale * m[:, None] * z + c, state, abs(scale) * m


def _scaled_about(z, scale, offset):
    return scale * z - np.asarray(offset, float) * (scale - 1)


def kifs_octahedral(z, c, state, scale=2.0, offset=(1, 0, 0), axis=(1, 1, 1), angle=0.0):
    z = -np.sort(-np.abs(z), axis=1)           # |x| >= |y| >= |z|
    z = _turn(z, axis, angle)
    return _scaled_about(z, scale, offset), state, np.full(len(z), float(scale))


def kifs_icosahedral(z, c, state, scale=2.618, offset=(1, 1, 1), axis=(0, 0, 1), angle=0.0,
                     axis2=(1, 0, 0), angle2=0.0):
    normals = [(-1, PHI - 1, 1 / (PHI - 1)), (PHI - 1, 1 / (PHI - 1), -1), (1 / (PHI - 1), -1, PHI - 1)]
    z = _turn(z, axis, angle)
    for _ in range(3):
        for n in normals:
            z = _mirror_below(z, n)
    z = _turn(_scaled_about(z, scale, offset), axis2, angle2)
    return z, state, np.full(len(z), float(scale))


def menger_ifs(z, c, state, scale=3.0, offset=(1, 1, 1), axis=(0, 0, 1), angle=0.0):
    """Knighty's step, his z-shift (z.z beyond the middle plane moved down)
    written as that plane's mirror: the same z up to the sign of z.z."""
    z = _turn(-np.sort(-np.abs(z), axis=1), axis, angle)
    z = scale * z - np.array([offset[0], offset[1], 0.0]) * (scale - 1)
    middle = 0.5 * offset[2] * (scale - 1)
    z[:, 2] = np.where(z[:, 2] > middle, 2 * middle - z[:, 2], z[:, 2])
    return z, state, np.full(len(z), float(scale))


def tetra_ifs(z, c, state, scale=2.0, offset=(1, 1, 1), axis=(1, 0, 0), angle=0.0):
    z = z.copy()
    for i, j in ((0, 1), (0, 2), (1, 2)):      # Knighty: if (x + y < 0) (x, y) = (-y, -x)
        swap = z[:, i] + z[:, j] < 0
        zi, zj = z[:, i].copy(), z[:, j].copy()
        z[:, i] = np.where(swap, -zj, zi)
        z[:, j] = np.where(swap, -zi, zj)
    return _scaled_about(_turn(z, axis, angle), scale, offset), state, np.full(len(z), float(scale))


def twist(z, c, state, axis=(0, 0, 1), angle=15.0):
    return _turn(z, axis, angle), state, np.ones(len(z))


def pseudo_kleinian(z, c, state, size=(0.92436, 0.90756, 0.92436), radius=1.0, thickness=0.0, extent=2.0):
    size = np.asarray(size, float)
    z = 2 * np.clip(z, -size, size) - z
    k = np.maximum(radius / np.maximum(np.sum(z * z, axis=1), 1e-30), 1.0)
    return z * k[:, None], {"k": state["k"] * k}, None


def pseudo_kleinian_distance(z, c, state, thickness=0.0, extent=2.0, **_):
    rxy = _norm(z[:, :2])
    de = (np.maximum(rxy - 0.92784, np.abs(rxy * z[:, 2]) / np.maximum(_norm(z), 1e-30)) - thickness) / state["k"]
    return np.maximum(de, _norm(c) - extent)


def apollonian(z, c, state, s=1.2, extent=2.0):
    z = -1 + 2 * ((0.5 * z + 0.5) - np.floor(0.5 * z + 0.5))    # Quilez: -1 + 2 fract(0.5 p + 0.5)
    k = s / np.maximum(np.sum(z * z, axis=1), 1e-30)
    return z * k[:, None], {"k": state["k"] * k}, None


def apollonian_distance(z, c, state, extent=2.0, **_):
    return np.maximum(0.25 * np.abs(z[:, 1]) / state["k"], _norm(c) - extent)


def quaternion_mandelbrot(q, c, state):
    x, v = q[:, :1], q[:, 1:]
    square = np.concatenate([x * x - np.sum(v * v, axis=1, keepdims=True), 2 * x * v], axis=1)
    return square + c, state, 2 * _norm(q)


def bulb(z, c, state, power=8.0):
    r = _norm(z)
    with np.errstate(divide="ignore", invalid="ignore"):
        theta = np.where(r == 0, 0.0, np.arccos(np.clip(z[:, 2] / r, -1, 1))) * power
        phi = np.arctan2(z[:, 1], z[:, 0]) * power
        rn = r ** power
    zn = rn[:, None] * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = power * r ** (power - 1)
    return zn + c, state, factor


def bristorbrot(z, c, state):
    x, y, w = z.T
    return np.stack([x * x - y * y - w * w, y * (2 * x - w), w * (2 * x + y)], axis=1) + c, state, None


def benesi(z, c, state):
    x, y, w = z.T
    r1 = y * y + w * w
    rho = np.sqrt(np.maximum(r1, 1e-30))
    new_x = np.where((c[:, 0] < 0) | (x < rho), x * x - r1, r1 - x * x)
    k = -2 * np.abs(x) / rho
    return np.stack([new_x, k * (y * y - w * w), k * 2 * y * w], axis=1) + c, state, None


def xenodreambuie(z, c, state, power=8.0, alpha=0.0, beta=0.0):
    """Jesse's step: the polar angle, beyond +-90 degrees, mirrored back."""
    r = np.maximum(_norm(z), 1e-30)
    th = (np.arctan2(z[:, 1], z[:, 0]) + np.radians(beta)) * power
    ph = np.arccos(np.clip(z[:, 2] / r, -1, 1)) + np.radians(alpha)
    ph = np.where(np.abs(ph) > np.pi / 2, np.sign(ph) * np.pi - ph, ph) * power
    direction = np.stack([np.cos(th) * np.sin(ph), np.sin(th) * np.sin(ph), np.cos(ph)], axis=1)
    return r[:, None] ** power * direction + c, state, None


def riemann_sphere(z, c, state, scale=1.0, shift=(0, 0, 0), escape=1.5):
    r = np.maximum(_norm(z), 1e-30)
    z = z * (scale / r)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = 1 / (1 - z[:, 2])
        s, t = z[:, 0] * q, z[:, 1] * q
        p = np.minimum(1 + s * s + t * t, 36)
        s, t = np.abs(np.sin(np.pi * s)), np.abs(np.sin(np.pi * t))
        k = (np.power(r * r, p) - 0.25) / (1 + s * s + t * t)
    return np.stack([2 * s, 2 * t, s * s + t * t - 1], axis=1) * k[:, None] + np.asarray(shift), state, None


# ---- orbits and estimates ---------------------------------------------------------

ADDS_C = {amazing_box, amazing_surf, abox_mod_kali, quaternion_mandelbrot, bulb}


def orbit(steps, points, iterations, bailout=None, julia=None, dims=3, state=None):
    """`steps`: [(step, params)] applied in turn, `iterations` steps in all.
    Returns the last z, the carried state and the scalar running derivative
    (dr -> factor dr, + 1 where the step adds c and c is the point; None if
    a step has no factor)."""
    points = np.asarray(points, float)
    n = len(points)
    z = np.concatenate([points, np.zeros((n, dims - 3))], axis=1)
    c = np.broadcast_to(np.asarray(julia, float), z.shape) if julia is not None else z.copy()
    state = {k: np.full(n, v, float) for k, v in (state or {}).items()}
    dr = np.ones(n)
    scalar = True
    stopped = np.zeros(n, bool)
    for i in range(iterations):
        step, params = steps[i % len(steps)]
        going = ~stopped
        if bailout is not None:
            going &= _norm(z) <= bailout
        with np.errstate(all="ignore"):
            new, new_state, factor = step(z, c, state, **params)
            ok = going & (np.sum(new * new, axis=1) <= OVERFLOW ** 2)
        z = np.where(ok[:, None], new, z)
        state = {k: np.where(ok, new_state[k], v) for k, v in state.items()}
        if factor is None:
            scalar = False
        else:
            grown = np.minimum(factor * dr + (1.0 if julia is None and step in ADDS_C else 0.0), DR_CAP)
            dr = np.where(ok, grown, dr)
        stopped |= going & ~ok
    return z, state, dr if scalar else None


def escape_time(r, gradient):
    """0.5 r ln r / |grad r| (0 at r = 0, at most 1e30)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        de = np.minimum(0.5 * r * np.log(r) / np.abs(gradient), 1e30)
    return np.where(r == 0, 0.0, de)


def jacobian(run, points, h=1e-6):
    """d z_n / d p of `run(points) -> z` by central differences,
    Richardson-extrapolated (error O(h^4)); also whether the two step
    sizes agree to `smooth` (False where a fold or a branch lies within h)."""
    points = np.asarray(points, float)
    columns, agree = [], np.ones(len(points), bool)
    for j in range(3):
        e = np.zeros(3)
        e[j] = 1.0

        def central(step):
            return (run(points + step * e) - run(points - step * e)) / (2 * step)
        coarse, fine = central(2 * h), central(h)
        column = fine + (fine - coarse) / 3
        scale = np.maximum(np.abs(column).max(axis=1), 1e-12)
        agree &= np.abs(fine - coarse).max(axis=1) < 1e-4 * scale
        columns.append(column)
    return np.stack(columns, axis=2), agree


def gradient_length(z, jac):
    """|grad |z|| = |J^T z| / |z|."""
    return _norm(np.einsum("nij,ni->nj", jac, z)) / _norm(z)
