"""The generated code is lean: values computed from params alone are
derived params (fractalc/hoist.py), computed once per launch, never per
estimate or per iteration."""
import re

import numpy as np
import pytest

import fractalc
from fractalc.emit import Target, emit_distance
from fractalc.lower import lower

BULB = """
param power = 8 in [2, 16]
param angle = 30 in [0, 90]
scene mandelbulb(power: power, iterations: 12, bailout: 2).rotate((0, 0, 1), angle * 2)
render { width: 64, height: 48 }
"""


def _function(source: str, name: str) -> str:
    """The text of the C function `name` (its signature to its closing brace)."""
    found = re.search(rf"^(\w+ )?{name}\(.*?^}}", source, re.M | re.S)
    assert found, name
    return found.group(0)


@pytest.mark.parametrize("lanes", [1, 8])
def test_param_only_values_leave_the_estimate(lanes):
    source = fractalc.loads(BULB).kernel_source(lanes=lanes)
    # cone marching's copy of the estimate, on vector lanes
    estimates = ["distance_estimate"] + ["uniform_distance_estimate"] * (lanes > 1)
    # the same scene with the angle written in: its rotation's sine and cosine are constants
    folded = fractalc.loads(BULB.replace("angle * 2", "60")).kernel_source(lanes=lanes)
    for name in estimates:
        body = _function(source, name)
        # the bound radius pow(2, 1 / (power - 1)) and the rotation's trigonometry
        assert not re.search(r"\b(pow|\w*bound_radius)\(", body), (name, body)
        trigonometry = re.compile(r"\b(sin|cos)\(")
        assert len(trigonometry.findall(body)) == len(trigonometry.findall(_function(folded, name)))
    kernel = _function(source, "__kernel void derived_params")
    assert re.search(r"\b\w*mandelbulb_bound_radius\(", kernel)
    assert re.search(r"\b(sin|cos)\(", kernel)


def test_distance_program_hoists_too():
    scene = fractalc.loads(BULB)
    source = emit_distance(lower(scene.checked), Target(lanes=8))
    assert not re.search(r"\b(pow|\w*bound_radius)\(", _function(source, "distance_estimate"))
    assert "__kernel void derived_params" in source


def test_derived_params_follow_the_params():
    # the derived values are computed again for new param values: the
    # distances equal those of the scene with the values written in
    scene = fractalc.loads(BULB)
    points = np.random.default_rng(3).uniform(-1.3, 1.3, (64, 3))
    for power, angle in ((8, 30), (3.5, 70)):
        scene.set_params({"power": power, "angle": angle})
        literal = fractalc.loads(BULB.replace("power: power", f"power: {power}").replace("angle * 2", f"{angle * 2}"))
        assert np.allclose(scene.distance(points), literal.distance(points), rtol=1e-5, atol=1e-6)
