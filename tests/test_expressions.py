"""The expression core scenes and formulas share (fractalc/expressions.py):
one message for one mistake in either. No OpenCL."""
import pytest

from fractalc import ir
from fractalc.check import check
from fractalc.errors import SceneError
from fractalc.expressions import broadcast
from fractalc.parse import parse
from fractalc.types import Type


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
