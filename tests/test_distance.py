"""`scene.distance` (the compiled OpenCL kernel) against the float64 numpy
reference in `reference.py`, for every shape and operation of LANGUAGE.md."""

import numpy as np
import pytest

import fractalc
import reference as ref

pytestmark = pytest.mark.opencl

S = ref.shape
POINTS = np.random.default_rng(20240521).uniform(-3, 3, (2000, 3))

# Error is |d - ref| / max(|ref|, SCALE). The kernel works on coordinates up
# to ~5 in magnitude, so its rounding error is absolute (about ulp(|p|)), not
# relative to a small distance near the surface: below a distance of SCALE the
# bound becomes an absolute one.
SCALE = 1.0
TOLERANCE = {"float": 1e-5, "double": 1e-12}
NEAR_SURFACE = {"float": 1e-2, "double": 0.0}  # points closer are not compared

# Operands shared by the combination cases, as (text, reference).
A, REF_A = "sphere(1.2)", S(ref.sphere, 1.2)
B, REF_B = (
    "box((1, 2, 0.8)).translate((0.7, 0.2, 0))",
    S(ref.translate, S(ref.box, (1, 2, 0.8)), (0.7, 0.2, 0)),
)
C, REF_C = (
    "torus(1, 0.3).rotate((1, 0, 0), 90)",
    S(ref.rotate, S(ref.torus, 1, 0.3), (1, 0, 0), 90),
)
BOX, REF_BOX = "box((1, 2, 0.5))", S(ref.box, (1, 2, 0.5))


def half_diagonal(size):
    return 0.5 * float(np.linalg.norm(size))


def case(text, expected, params=None):
    name = text.replace("\n", "; ") + (f" {params}" if params else "")
    return pytest.param(text, params, expected, id=name)


CASES = [
    # ---- primitives, defaults and arguments
    case("scene sphere()", S(ref.sphere)),
    case("scene sphere(1.5)", S(ref.sphere, 1.5)),
    case("scene sphere(radius: 0.3)", S(ref.sphere, 0.3)),
    case("scene box()", S(ref.box)),
    case("scene box(1.7)", S(ref.box, 1.7)),
    case("scene box((1, 2, 0.5))", S(ref.box, (1, 2, 0.5))),
    case("scene box(size: (0.4, 2.5, 1))", S(ref.box, (0.4, 2.5, 1))),
    case("scene plane()", S(ref.plane)),
    case("scene plane(normal: (1, 2, 2), offset: 0.5)", S(ref.plane, (1, 2, 2), 0.5)),
    case("scene plane((0, -3, 4), -1)", S(ref.plane, (0, -3, 4), -1)),
    case("scene torus()", S(ref.torus)),
    case("scene torus(1.5, 0.4)", S(ref.torus, 1.5, 0.4)),
    case("scene torus(minor: 0.6, major: 0.8)", S(ref.torus, 0.8, 0.6)),
    case("scene cylinder()", S(ref.cylinder)),
    case("scene cylinder(1, 0.5)", S(ref.cylinder, 1, 0.5)),
    case("scene cylinder(height: 3)", S(ref.cylinder, height=3)),
    case("scene capsule()", S(ref.capsule)),
    case("scene capsule((1, 0, 0), (-1, 1, 0.5), 0.3)",
         S(ref.capsule, (1, 0, 0), (-1, 1, 0.5), 0.3)),
    case("scene capsule(radius: 0.6, a: (0.5, 0.5, 0.5), b: (0.5, 0.5, 0.5))",
         S(ref.capsule, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5), 0.6)),
    # ---- combinations
    case(f"scene union({A}, {B})", S(ref.union, REF_A, REF_B)),
    case(f"scene union({A}, {B}, smooth: 0.3)", S(ref.union, REF_A, REF_B, smooth=0.3)),
    case(f"scene union({A}, {B}, smooth: 0)", S(ref.union, REF_A, REF_B)),
    case(f"scene union({A}, {B}, {C})", S(ref.union, REF_A, REF_B, REF_C)),
    case(f"scene union({A}, {B}, {C}, smooth: 0.4)", S(ref.union, REF_A, REF_B, REF_C, smooth=0.4)),
    case(f"scene intersect({A}, {B})", S(ref.intersect, REF_A, REF_B)),
    case(f"scene intersect({A}, {B}, smooth: 0.3)", S(ref.intersect, REF_A, REF_B, smooth=0.3)),
    case(f"scene intersect({A}, {B}, {C}, smooth: 0.25)",
         S(ref.intersect, REF_A, REF_B, REF_C, smooth=0.25)),
    case(f"scene subtract({A}, {B})", S(ref.subtract, REF_A, REF_B)),
    case(f"scene subtract({A}, {B}, smooth: 0.3)", S(ref.subtract, REF_A, REF_B, smooth=0.3)),
    case(f"scene {A} | {B}", S(ref.union, REF_A, REF_B)),
    case(f"scene {A} & {B}", S(ref.intersect, REF_A, REF_B)),
    case(f"scene {A} - {B}", S(ref.subtract, REF_A, REF_B)),
    case(f"scene {A} | {B} | {C}", S(ref.union, REF_A, REF_B, REF_C)),
    case(f"scene {A} - {B} - {C}", S(ref.subtract, S(ref.subtract, REF_A, REF_B), REF_C)),
    case(f"scene ({A} | {B}) & {C}", S(ref.intersect, S(ref.union, REF_A, REF_B), REF_C)),
    # ---- positioning
    case(f"scene {BOX}.translate((1, -0.5, 0.25))", S(ref.translate, REF_BOX, (1, -0.5, 0.25))),
    case(f"scene {BOX}.rotate((1, 2, 3), 37)", S(ref.rotate, REF_BOX, (1, 2, 3), 37)),
    case(f"scene {BOX}.rotate((0, 0, 1), 90)", S(ref.rotate, REF_BOX, (0, 0, 1), 90)),
    case(f"scene {BOX}.rotate((0, -1, 0), -120)", S(ref.rotate, REF_BOX, (0, -1, 0), -120)),
    case(f"scene {BOX}.scale(0.5)", S(ref.scale, REF_BOX, 0.5)),
    case(f"scene {B}.scale(2.5)", S(ref.scale, REF_B, 2.5)),
    case("scene sphere(0.4).repeat(1.5)", S(ref.repeat, S(ref.sphere, 0.4), 1.5)),
    case("scene box((0.5, 0.3, 0.8)).repeat((2, 0, 1.25))",
         S(ref.repeat, S(ref.box, (0.5, 0.3, 0.8)), (2, 0, 1.25))),
    case(f"scene {B}.scale(0.3).repeat((1, 1.5, 0))",
         S(ref.repeat, S(ref.scale, REF_B, 0.3), (1, 1.5, 0))),
    # ---- alterations
    case(f"scene {BOX}.round(0.2)", S(ref.round_, REF_BOX, 0.2)),
    case("scene sphere(1.2).onion(0.1)", S(ref.onion, S(ref.sphere, 1.2), 0.1)),
    case(f"scene ({A} - {B}).onion(0.1).round(0.05)",
         S(ref.round_, S(ref.onion, S(ref.subtract, REF_A, REF_B), 0.1), 0.05)),
    # (held in the sphere about the origin through a box's corners, or a torus's outer rim)
    case("scene box((1, 1, 3)).twist(0.8)", S(ref.twist, S(ref.box, (1, 1, 3)), 0.8, half_diagonal((1, 1, 3)))),
    case(f"scene {BOX}.twist(-1.5)", S(ref.twist, REF_BOX, -1.5, half_diagonal((1, 2, 0.5)))),
    case("scene box((3, 0.5, 0.5)).bend(0.6)",
         S(ref.bend, S(ref.box, (3, 0.5, 0.5)), 0.6, half_diagonal((3, 0.5, 0.5)))),
    case(f"scene {C}.bend(-0.3)", S(ref.bend, REF_C, -0.3, 1.3)),
    # off the axis: the sphere about the axis point nearest the shape's
    # centre, through the shape's farthest point from it
    case("scene box(0.6).translate((1, 0.5, 2)).twist(0.7)",
         S(ref.twist, S(ref.translate, S(ref.box, 0.6), (1, 0.5, 2)), 0.7,
           np.hypot(1, 0.5) + half_diagonal((0.6, 0.6, 0.6)), (0, 0, 2))),
    # ---- material and colour leave the distance alone
    case(f"scene {A}.color((1, 0, 0))", REF_A),
    case(f"material m {{ color: (1, 0.5, 0) }}\nscene {BOX}.material(m) | {A}.color((0, 1, 0))",
         S(ref.union, REF_BOX, REF_A)),
    # ---- nested transforms
    case(f"scene {BOX}.rotate((1, 2, 3), 37).translate((0.5, 0, -1)).scale(1.5)",
         S(ref.scale, S(ref.translate, S(ref.rotate, REF_BOX, (1, 2, 3), 37), (0.5, 0, -1)), 1.5)),
    case("scene (sphere(0.5).translate((1, 0, 0)) | box(0.6)).repeat((3, 3, 0)).twist(0.4)",
         S(ref.twist, S(ref.repeat, S(ref.union, S(ref.translate, S(ref.sphere, 0.5), (1, 0, 0)),
                                      S(ref.box, 0.6)), (3, 3, 0)), 0.4)),
    case(f"scene {BOX}.twist(0.5).rotate((0, 1, 1), 45).bend(0.2)",
         S(ref.bend, S(ref.rotate, S(ref.twist, REF_BOX, 0.5, half_diagonal((1, 2, 0.5))), (0, 1, 1), 45), 0.2,
           half_diagonal((1, 2, 0.5)))),
    # ---- let and param in arguments
    case("let r = 0.6\nlet s = sphere(r * 2)\nscene s.translate((0, 0, r))",
         S(ref.translate, S(ref.sphere, 1.2), (0, 0, 0.6))),
    case("let v = (1, 2, 3)\nscene box(v / 2)", S(ref.box, (0.5, 1, 1.5))),
    case("param r = 0.7 in [0.1, 2]\nscene sphere(r)", S(ref.sphere, 0.7)),
    case("param r = 0.7 in [0.1, 2]\nscene sphere(r)", S(ref.sphere, 1.3), {"r": 1.3}),
    case("param t = 0.5\nscene box(1).translate((t, 0, 2 * t))",
         S(ref.translate, S(ref.box, 1), (-1, 0, -2)), {"t": -1}),
    case(f"param k = 0.2 in [0, 1]\nscene union({A}, {B}, smooth: k)",
         S(ref.union, REF_A, REF_B, smooth=0.6), {"k": 0.6}),
    case(f"param a = 30 in [0, 360]\nscene {BOX}.rotate((1, 2, 3), a)",
         S(ref.rotate, REF_BOX, (1, 2, 3), 100), {"a": 100}),
]


def load(text, precision, params, device=None):
    kwargs = {} if precision == "float" else {"precision": precision}
    if params is not None:
        kwargs["params"] = params
    return fractalc.loads(text, device=device, **kwargs)


@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("text, params, expected", CASES)
def test_distance_matches_reference(text, params, expected, precision):
    assert_matches(load(text, precision, params), expected, precision)


# one case of each kind: primitives, smooth combinations, positioning,
# deformations, params (the whole table runs on the default device)
EVERY_DRIVER = [c for c in CASES if c.id in (
    "scene sphere()", "scene capsule((1, 0, 0), (-1, 1, 0.5), 0.3)",
    f"scene union({A}, {B}, {C}, smooth: 0.4)", f"scene {A} - {B} - {C}",
    f"scene {BOX}.twist(0.5).rotate((0, 1, 1), 45).bend(0.2)",
    f"param a = 30 in [0, 360]; scene {BOX}.rotate((1, 2, 3), a) {{'a': 100}}")]


@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("text, params, expected", EVERY_DRIVER)
def test_distance_matches_reference_on_every_driver(text, params, expected, precision, driver):
    assert_matches(load(text, precision, params, driver), expected, precision)


def assert_matches(scene, expected, precision):
    d = np.asarray(scene.distance(POINTS), dtype=np.float64)
    want = expected(POINTS)
    assert d.shape == want.shape
    compared = np.abs(want) > NEAR_SURFACE[precision]
    error = np.where(compared, np.abs(d - want) / np.maximum(np.abs(want), SCALE), 0)
    worst = int(np.argmax(error))
    assert error[worst] < TOLERANCE[precision], (
        f"at {POINTS[worst]}: kernel {d[worst]:.17g}, reference {want[worst]:.17g}"
    )
