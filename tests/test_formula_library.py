"""The formula library (stdlib_frac/formulas.frac) against the independent
float64 numpy references of reference_formulas.py: the compiled kernel's
estimate in float and double, the compiler's derived Jacobian against
finite differences of the numpy orbit, the scalar and Jacobian paths on
conformal formulas (Julia mode), and finiteness in the hard cases with
parameters at their range ends.

Every formula of a case is compiled once per precision into one program,
its parameters kernel arguments (so the range ends need no rebuild)."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

import reference_formulas as ref
from fractalc import ast, check, formula_code, ir
from fractalc.emit import double_literals, function_source
from fractalc.parse import parse
from fractalc.types import Type

pytestmark = pytest.mark.emit

POINT = tuple(ir.Comp(ir.Var("p", ir.VEC3), i) for i in range(3))
# 95th percentile of the relative error; float: measured at most 4.0e-5
# (PoCL) and 8.3e-5 (Intel's runtime), both kifs_icosahedral
TOLERANCE = {"float": 2e-4, "double": 1e-9}
FLOOR = 1e-3                                      # relative to max(|reference|, FLOOR)


@dataclass(frozen=True)
class Case:
    """A fractal of library formulas with arguments (in the numpy step's
    names), run `iterations` steps; `estimate` names the reference: linear
    or escape (by the scalar running derivative), jacobian (escape time by
    finite differences) or own (the formula's own final distance)."""
    uses: tuple                       # (formula name, {param: value}) in turn
    iterations: int
    radius: float                     # the seeded points fill this ball
    estimate: str
    bailout: float | None = None
    julia: tuple | None = None
    dims: int = 3
    state: dict = field(default_factory=dict)

    @property
    def steps(self):
        return [(getattr(ref, name), params) for name, params in self.uses]


CASES = {
    "amazing_box": Case((("amazing_box", dict(scale=-1.7, fold=0.9, min_radius=0.4, fixed_radius=1.1)),),
                        10, 3.0, "linear"),
    "amazing_surf": Case((("amazing_surf", dict(scale=1.8, fold=1.0, min_radius=0.5, axis=(0, 1, 0),
                                                angle=12.0)),), 8, 3.0, "linear", bailout=100.0),
    "abox_mod_kali": Case((("abox_mod_kali", dict(scale=2.5, corner=(0.5, 0.5, 0.5), min_radius=0.7746,
                                                  axis=(1, 0, 0), angle=20.0)),), 8, 4.0, "linear", bailout=100.0),
    "kifs_octahedral": Case((("kifs_octahedral", dict(scale=2.0, offset=(1, 0, 0), axis=(1, 1, 1),
                                                      angle=20.0)),), 10, 1.2, "linear"),
    "kifs_icosahedral": Case((("kifs_icosahedral", dict(scale=2.618, offset=(1, 1, 1), axis=(0, 0, 1), angle=10.0,
                                                        axis2=(1, 0, 0), angle2=25.0)),), 8, 2.0, "linear"),
    "menger_ifs": Case((("menger_ifs", dict(scale=3.0, offset=(1, 1, 1), axis=(0, 0, 1), angle=10.0)),),
                       8, 2.0, "linear"),
    "tetra_ifs": Case((("tetra_ifs", dict(scale=2.0, offset=(1, 1, 1), axis=(1, 0, 0), angle=8.0)),),
                      10, 2.0, "linear"),
    "twist_menger": Case((("twist", dict(axis=(1, 1, 0), angle=20.0)), ("menger_ifs", dict(
        scale=3.0, offset=(1, 1, 1), axis=(0, 0, 1), angle=0.0))), 12, 2.0, "linear"),
    "pseudo_kleinian": Case((("pseudo_kleinian", dict(size=(0.92436, 0.90756, 0.92436), radius=1.0,
                                                      thickness=0.01, extent=2.0)),), 8, 2.2, "own",
                            state={"k": 1.0}),
    "apollonian": Case((("apollonian", dict(s=1.2, extent=2.0)),), 6, 2.2, "own", state={"k": 1.0}),
    "quaternion_mandelbrot": Case((("quaternion_mandelbrot", {}),), 8, 2.0, "escape", bailout=4.0, dims=4),
    "bulb": Case((("bulb", dict(power=7.0)),), 8, 1.3, "escape", bailout=2.0),
    "bristorbrot": Case((("bristorbrot", {}),), 6, 2.0, "jacobian", bailout=4.0),
    "benesi": Case((("benesi", {}),), 6, 2.0, "jacobian", bailout=4.0),
    "xenodreambuie": Case((("xenodreambuie", dict(power=7.0, alpha=10.0, beta=-20.0)),), 6, 1.3, "jacobian",
                          bailout=2.0),
    "riemann_sphere": Case((("riemann_sphere", dict(scale=1.0, shift=(0, 0, 0), escape=1.5)),), 5, 1.6,
                           "jacobian", bailout=1.5),
}
OWN = {"pseudo_kleinian": ref.pseudo_kleinian_distance, "apollonian": ref.apollonian_distance}
# conformal formulas whose step adds c: in Julia mode their scalar running derivative is exact
JULIA = {"amazing_box": (0.3, -0.4, 0.2), "amazing_surf": (0.3, -0.4, 0.2), "abox_mod_kali": (0.3, -0.4, 0.2)}


def library_names() -> set[str]:
    """The formulas of stdlib_frac/formulas.frac (not the built-ins' file)."""
    path = Path(__file__).resolve().parent.parent / "stdlib_frac" / "formulas.frac"
    return {d.name for d in parse(path.read_text(), str(path)).decls if isinstance(d, ast.FormulaDecl)}


def test_every_library_formula_has_a_case():
    library = library_names()
    covered = {name for case in CASES.values() for name, _ in case.uses}
    assert library == covered


# ---------------------------------------------------------------- the compiled orbit

def _library():
    return dict(check.library_formulas())


def _layout(case: Case):
    """Each formula's arguments as IR params (a vector as consecutive params),
    and the kernel's param values for `case`'s arguments (or `overrides`)."""
    library, index, uses = _library(), 0, []
    for name, _ in case.uses:
        formula, signature = library[name]
        args = []
        for p in signature.parameters:
            width = 1 if p.type is Type.NUMBER else len(p.default)
            params = tuple(ir.Param(index + k, f"{name}_{p.name}{k}") for k in range(width))
            args.append(params[0] if width == 1 else ir.Vec(params))
            index += width
        uses.append(formula_code.Use(formula, tuple(args)))
    return tuple(uses)


def param_values(case: Case, overrides=None) -> list[float]:
    library, values = _library(), []
    for k, (name, given) in enumerate(case.uses):
        _, signature = library[name]
        for p in signature.parameters:
            value = (overrides or {}).get((k, p.name), given.get(p.name, p.default))
            values.extend(np.ravel(value).tolist())
    return values


def orbit_ir(case: Case, jacobian=None, julia=None, constants=True):
    """The estimate's IR: with the case's arguments as constants (for the
    float64 IR evaluator) or as params (for the kernel)."""
    uses = _layout(case)
    values = param_values(case)
    constant_uses = tuple(formula_code.Use(u.formula, tuple(
        ir.Vec(tuple(ir.const(values[x.index]) for x in a.items)) if isinstance(a, ir.Vec)
        else ir.const(values[a.index]) for a in u.args)) for u in uses)
    bailout = None if case.bailout is None else ir.const(case.bailout)
    julia = julia if julia is not None else case.julia
    julia = None if julia is None else ir.Vec(tuple(ir.const(x) for x in julia))
    # the estimate's kind as the checker measures it, at the case's argument values
    estimate = formula_code.growth(constant_uses, julia).estimate
    return formula_code.orbit(constant_uses if constants else uses, POINT, ir.Const(float(case.iterations), ir.INT),
                              bailout, julia, jacobian=jacobian, estimate=estimate)


_KERNEL = """
__kernel VECTOR_LANES_HINT void k_{name}(__global const scalar *x, __global const scalar *y, __global const scalar *z,
                       __constant scalar *params, __global scalar *out) {{
    int i = get_global_id(0);
    out[i] = f_{name}(v3(x[i], y[i], z[i]), params);
}}
"""


@lru_cache(maxsize=None)
def _program(precision: str):
    """Every case's estimate in one program (1 lane), built once."""
    import pyopencl as cl
    import fractalc
    from fractalc.stdlib import library
    parts = ["#define LANES 1", f"#define PRECISION_DOUBLE {int(precision == 'double')}", "#define FAST_MATH 0",
             library().prelude]
    for name, case in CASES.items():
        distance = orbit_ir(case, constants=False).distance
        parts.append(function_source(distance, f"real f_{name}(vec3 p, __constant scalar *params)"))
        parts.append(_KERNEL.format(name=name))
    source = "\n".join(parts)
    if precision == "double":
        source = double_literals(source)
    device = fractalc.loads("scene sphere(1)").device
    return device, cl.Program(device.context, source).build()


@lru_cache(maxsize=None)
def _kernel(name: str, precision: str):
    import pyopencl as cl
    device, program = _program(precision)
    return device, cl.Kernel(program, f"k_{name}")


def kernel_distance(name, points, precision, params) -> np.ndarray:
    import pyopencl as cl
    device, kernel = _kernel(name, precision)
    dtype = np.float64 if precision == "double" else np.float32
    points = np.asarray(points, float)
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    xyz = [cl.Buffer(device.context, flags, hostbuf=np.ascontiguousarray(points[:, k], dtype=dtype))
           for k in range(3)]
    out = np.empty(len(points), dtype)
    out_buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    params = cl.Buffer(device.context, flags, hostbuf=np.asarray([*params, 0.0], dtype))   # never empty
    kernel(device.queue, (len(points),), None, *xyz, params, out_buffer)
    cl.enqueue_copy(device.queue, out, out_buffer)
    return out.astype(np.float64)


# ---------------------------------------------------------------- the numpy estimates

def points_in(case: Case, count: int, seed: int = 11) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * case.radius * rng.uniform(0, 1, (count, 1)) ** (1 / 3)


def _final_z(case: Case, julia=None):
    return lambda p: ref.orbit(case.steps, p, case.iterations, case.bailout, julia, case.dims, case.state)[0]


def finite_difference_estimate(case: Case, points, julia=None):
    """The estimate from the finite-difference Jacobian of the numpy orbit
    (linear or escape time), and where that Jacobian is trustworthy."""
    z = _final_z(case, julia)(points)
    jac, smooth = ref.jacobian(_final_z(case, julia), points)
    gradient = ref.gradient_length(z, jac)
    r = np.linalg.norm(z, axis=1)
    de = r / gradient if case.estimate == "linear" else ref.escape_time(r, gradient)
    if case.uses[0][0] == "riemann_sphere":
        de = np.where(r <= case.uses[0][1]["escape"], 0.0, de)
    return de, smooth


def reference_estimate(case: Case, points):
    """The numpy estimate of the case, and where it is trustworthy."""
    z, state, dr = ref.orbit(case.steps, points, case.iterations, case.bailout, case.julia, case.dims, case.state)
    r = np.linalg.norm(z, axis=1)
    everywhere = np.ones(len(points), bool)
    if case.estimate == "own":
        name, params = case.uses[0]
        return OWN[name](z, points, state, **params), everywhere
    if case.estimate == "linear":
        return r / dr, everywhere
    if case.estimate == "escape":
        return ref.escape_time(r, dr), everywhere
    return finite_difference_estimate(case, points)


def relative(a, b):
    return np.abs(a - b) / np.maximum(np.abs(b), FLOOR)


# ---------------------------------------------------------------- the tests

@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_estimate_matches_the_numpy_reference(name, precision):
    case = CASES[name]
    points = points_in(case, 48)
    expected, trusted = reference_estimate(case, points)
    got = kernel_distance(name, points, precision, param_values(case))
    assert np.isfinite(got).all()
    assert trusted.sum() >= len(points) // 2
    error = np.percentile(relative(got[trusted], expected[trusted]), 95)
    assert error < TOLERANCE[precision], f"95th percentile relative error {error:.3g}"


DERIVED = sorted(name for name, case in CASES.items() if case.estimate != "own")


@pytest.mark.parametrize("name", DERIVED)
def test_derived_jacobian_estimate_matches_finite_differences(name):
    """The compiler's forward-mode Jacobian (float64 IR) against finite
    differences of the numpy orbit, where the orbit is smooth."""
    case = CASES[name]
    points = points_in(case, 40, seed=5)
    expected, smooth = finite_difference_estimate(case, points)
    got, = ir.evaluate_at((orbit_ir(case, jacobian=True).distance,), points)
    assert smooth.sum() >= len(points) // 2, "too few points where the orbit is smooth"
    error = relative(got[smooth], expected[smooth]).max()
    assert error < 1e-6, f"largest relative error {error:.3g}"


# (not quaternion_mandelbrot: in its 3D slice the gradient of |q| is at most
# the 4D running derivative, not equal to it)
CONFORMAL = sorted(name for name, case in CASES.items() if case.estimate == "linear")


@pytest.mark.parametrize("name", CONFORMAL)
def test_scalar_and_jacobian_paths_agree_on_conformal_formulas(name):
    """In Julia mode (c fixed) a similarity's running derivative is exact:
    the scalar path and the Jacobian path give the same estimate."""
    case = CASES[name]
    julia = JULIA.get(name)
    scalar, full = orbit_ir(case, jacobian=False, julia=julia), orbit_ir(case, jacobian=True, julia=julia)
    assert scalar.scalar and not full.scalar
    points = points_in(case, 64, seed=3)
    a, b = ir.evaluate_at((scalar.distance, full.distance), points)
    assert np.allclose(a, b, rtol=1e-9, atol=1e-12)


def _range_ends(case: Case):
    """The case's arguments, then every ranged parameter at its low end, then
    at its high end."""
    library = _library()
    ends = [{}, {}]
    for k, (name, _) in enumerate(case.uses):
        for p in library[name][1].parameters:
            if p.constraints:
                low, high = p.constraints[0].low, p.constraints[0].high
                ends[0][(k, p.name)], ends[1][(k, p.name)] = low, high
    return [param_values(case)] + [param_values(case, e) for e in ends]


def hard_points(case: Case) -> np.ndarray:
    edge = case.bailout or case.radius
    diagonal = np.ones(3) / np.sqrt(3)
    return np.array([[0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 0, 1], [0.5, 0, 0], [0, 0, -2],
                     *(edge * diagonal * s for s in (1 - 1e-7, 1, 1 + 1e-7)), [edge, 0, 0],
                     1e6 * diagonal, [-1e6, 0, 0], [0, 0, 1e6]])


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_hard_cases_are_finite(name, precision):
    """The origin, the axes, the bailout sphere and |p| = 1e6, with the
    parameters at their range ends."""
    case = CASES[name]
    for values in _range_ends(case):
        d = kernel_distance(name, hard_points(case), precision, values)
        assert np.isfinite(d).all(), f"params {values}: {d}"


# ---------------------------------------------------------------- the examples

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((REPO / "examples" / "formulas").glob("*.frac"))


def _fractal(path):
    import fractalc
    shape = fractalc.load(path).checked.shape
    while not hasattr(shape, "sequence"):       # under its material and colouring
        shape = shape.shape
    return shape


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_each_examples_bound_holds_its_fractal(path):
    """Beyond `bound: R` (R to 1.5 R) the estimate (float64 IR, no bound)
    stays above the surface level of `check --de` (1e-5 R): no surface is cut."""
    shape = _fractal(path)
    radius = shape.bound.value
    rng = np.random.default_rng(0)
    points = rng.normal(size=(300, 3))
    points *= radius * rng.uniform(1, 1.5, (300, 1)) / np.linalg.norm(points, axis=1, keepdims=True)
    distance = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout, shape.julia).distance
    d, = ir.evaluate_at((distance,), points)
    assert d.min() > 1e-5 * radius


def test_the_docs_table_lists_every_library_formula_with_its_example_and_image():
    text = (REPO / "docs" / "formulas.md").read_text()
    for name in library_names():
        assert f"| `{name}(" in text, name
    for path in EXAMPLES:
        assert f"(../examples/formulas/{path.name})" in text, path.name
        assert f"(gallery/formulas/{path.stem}.png)" in text, path.stem
        assert (REPO / "docs" / "gallery" / "formulas" / f"{path.stem}.png").is_file(), path.stem
