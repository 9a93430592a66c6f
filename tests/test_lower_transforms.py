"""The transforms' table (fractalc/transforms.py TRANSFORMS): each
transform of the language is one entry holding its signature and its
lowering (point map, distance fix, bound update), and an entry without
one of them stops the import. Pure Python: no OpenCL."""
import dataclasses
import subprocess
import sys

import pytest

from fractalc import ir, lower, transforms

import fractalc

pytestmark = pytest.mark.emit


def test_every_transform_of_the_language_has_its_signature_and_three_lowering_parts():
    parts = [f for f in dataclasses.fields(transforms.Transform)]
    assert [f.name for f in parts] == ["signature", "point", "distance", "bound"]
    assert all(f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING for f in parts)
    assert all(t.signature.name == name and t.signature.kind == "transform"
               for name, t in transforms.TRANSFORMS.items())
    assert set(transforms.SIGNATURES) == {*transforms.TRANSFORMS, "material", "color"}
    with pytest.raises(TypeError):      # no bound update
        transforms.Transform(transforms.TRANSFORMS["twist"].signature, lambda point, args: point,
                             lambda d, args, point, inner_bound: d)


def test_a_transform_without_its_lowering_stops_the_import():
    code = ("import importlib\n"
            "from fractalc import transforms\n"
            "source = open(transforms.__file__).read()\n"
            "source = source.replace('\"onion\": Transform(', '\"shear\": Transform(_signature(\"shear\")), '\n"
            "                        '\"onion\": Transform(')\n"
            "exec(compile(source, transforms.__file__, 'exec'), {'__name__': 'fractalc.transforms', "
            "'__package__': 'fractalc'})\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert "TypeError: Transform.__init__() missing 3 required positional arguments" in result.stderr


def _bound(text):
    return lower.lower(fractalc.loads(f"scene {text}").checked).bound


def test_each_transform_updates_the_bound_as_its_entry_says():
    def sphere(text):
        centre, radius = _bound(text).sphere
        assert all(ir.is_const(c) for c in centre)
        return tuple(c.value for c in centre), radius
    one = ir.call("sphere_bound_radius", (ir.const(1.0),))     # sphere(1)'s bounding radius
    assert sphere("sphere(1).translate((1, 2, 3))") == ((1.0, 2.0, 3.0), one)
    assert sphere("sphere(1).translate((1, 0, 0)).scale(2)") == ((2.0, 0.0, 0.0), ir.mul(one, ir.const(2.0)))
    assert sphere("sphere(1).round(0.5)") == ((0.0, 0.0, 0.0), ir.add(one, ir.const(0.5)))
    assert sphere("sphere(1).onion(0.1)") == ((0.0, 0.0, 0.0), one)
    # a twist keeps the sphere about the z axis through the centre's height
    assert sphere("sphere(1).translate((3, 4, 5)).twist(1)") == ((0.0, 0.0, 5.0), ir.add(one, ir.const(5.0)))
    centre, radius = sphere("sphere(1).translate((1, 0, 0)).rotate((0, 0, 1), 90)")
    assert centre == pytest.approx((0.0, 1.0, 0.0), abs=1e-12) and radius == one
    assert _bound("sphere(1).repeat(4)") is None
    # a ground half-space is moved by a translate, and dropped by a warp
    (normal, offset), = _bound("sphere(1) | plane().translate((0, 0, -1))").half_spaces
    assert offset.value == -1.0
    assert _bound("(sphere(1) | plane()).twist(1)") is None
