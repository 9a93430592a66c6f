"""The engine's files (stdlib_cl/engine/, stdlib.ENGINE), the emitter's
templates (stdlib_cl/shade.cl, scene.cl) and the counting build's hooks:
pure Python, no OpenCL."""
import re

import pytest

from fractalc import stdlib
from fractalc.emit import resolve_features
from fractalc.resources import resource_dir


def test_the_engine_lists_every_file_of_its_folder_once():
    folder = resource_dir("stdlib_cl") / stdlib.ENGINE_DIR
    assert len(set(stdlib.ENGINE)) == len(stdlib.ENGINE)
    assert sorted(stdlib.ENGINE) == sorted(path.stem for path in folder.glob("*.cl"))


@pytest.mark.parametrize("name", stdlib.ENGINE)
def test_each_engine_file_closes_what_it_opens(name):
    """An engine file is whole on its own: its #if blocks and braces close in it."""
    text = (resource_dir("stdlib_cl") / stdlib.ENGINE_DIR / f"{name}.cl").read_text()
    lines = text.splitlines()
    assert sum(line.startswith("#if") for line in lines) == sum(line.startswith("#endif") for line in lines)
    code = re.sub(r"//[^\n]*", "", text)
    assert code.count("{") == code.count("}")


def test_a_template_is_filled_in_or_refused():
    lit = stdlib.templates("shade.cl")["lit"]
    filled = lit.substitute(to_light="to_light", radiance="radiance")
    assert "$" not in filled and "blinn_phong(normal, to_light, to_eye" in filled
    with pytest.raises(KeyError):
        lit.substitute(to_light="to_light")


def test_counting_hooks_stay_only_in_the_counting_build():
    text = "real d = 0.0f;\n    COUNT_EVALUATIONS(COUNT_CAMERA, active, 1.0f);\n    COUNT_SCOPE(hit);\nreturn d;"
    assert resolve_features(text, {"COUNT": False}) == "real d = 0.0f;\nreturn d;"
    assert resolve_features(text, {"COUNT": True}) == text
