"""The expression core scenes and formulas share (fractalc/expressions.py):
one message for one mistake in either. No OpenCL."""
import pytest

from fractalc import ir
from fractalc.check import check
from fractalc.errors import SceneError
from fractalc.expressions import broadcast
from fractalc.parse import parse
from fractalc.types import Type

pytestmark = pytest.mark.check


def _message(text: str) -> str:
    with pytest.raises(SceneError) as raised:
        check(parse(text, "scene.frac"))
    return raised.value.message


def test_a_component_mistake_reads_the_same_in_a_scene_and_in_a_formula():
    in_scene = _message("let v = (1, 2, 3)\nscene sphere(v.w)")
    in_formula = _message("formula f() {\n  z = z + (1, 2, 3).w\n}\nscene fractal(f(), iterations: 4)")
    assert in_scene == in_formula == "'.w' is not a component of a 3-vector (components: x, y, z)"


def test_numbers_broadcast_over_vectors_of_one_size():
    one, two = ir.const(1.0), ir.const(2.0)
    size, lanes = broadcast([(Type.NUMBER, (one,)), (Type.VEC3, (one, two, one))])
    assert size == 3 and lanes[0] == (one, one, one)
    assert broadcast([(Type.NUMBER, (one,)), (Type.NUMBER, (two,))]) == (1, [(one,), (two,)])
    assert broadcast([(Type.VEC2, (one, two)), (Type.VEC3, (one, two, one))]) is None


def _in_formula(step: str) -> str:
    return _message(f"formula f() {{\n  {step}\n}}\nscene fractal(f(), iterations: 4)")


@pytest.mark.parametrize("scene, step, message", [
    ("let v = (1, 2) + (1, 2, 3)\nscene sphere(1)", "z = z + (1, 2)",
     "'+' on vectors of different sizes (2 and 3)"),
    ("let v = dot((1, 2), (1, 2, 3))\nscene sphere(1)", "z = z * dot(z, (1, 2))",
     "'dot' on vectors of different sizes (2 and 3)"),
    ("let v = sin\nscene sphere(1)", "z = z * sin", "'sin' is a function: call it, e.g. 'sin(...)'"),
    ("let v = sin(1, 2)\nscene sphere(1)", "z = z * sin(1, 2)", "'sin' takes 1 argument (sin(x)), not 2"),
    ("let v = sin(x: 1)\nscene sphere(1)", "z = z * sin(x: 1)", "'sin' takes its arguments in order, without names"),
    ("let v = length(1)\nscene sphere(1)", "z = z * length(1)",
     "'length' needs a vector here (length(v)), this is a number"),
    ("let v = log(0)\nscene sphere(1)", "z = z * log(0)", "'log' is undefined for these values"),
    ("let v = exp(100)\nscene sphere(1)", "z = z * exp(100)",
     "'exp' gives 2.69e+43, beyond the kernel's floats (3.4e+38)"),
    ("let v = (1, sphere(1))\nscene sphere(1)", "z = (1, 1 < 2, 3)", None),
])
def test_a_mistake_both_find_reads_the_same_in_a_scene_and_in_a_formula(scene, step, message):
    in_scene, in_formula = _message(scene), _in_formula(step)
    if message is None:     # what each may hold differs: the sentence is one
        assert in_scene.startswith("a vector's components must be numbers, this is ")
        assert in_formula == "a vector's components must be numbers, this is a comparison"
    else:
        assert in_scene == in_formula == message


def test_an_empty_range_reads_the_same_for_a_param_and_a_formula_parameter():
    in_scene = _message("param p = 1 in [3, 1]\nscene sphere(1)")
    in_formula = _message("formula f(s = 2 in [3, 1]) {\n  z = z * s + c\n}\nscene fractal(f(), iterations: 4)")
    assert in_scene == in_formula == "the range [3, 1] is empty"
