"""The engine's files (stdlib_cl/engine/, stdlib.ENGINE), the emitter's
templates (stdlib_cl/shade.cl, scene.cl), the counting build's hooks and
the features and constants the keys declare for the kernel: pure Python,
no OpenCL."""
import re

import pytest

from fractalc import stdlib
from fractalc.emit import resolve_features
from fractalc.resources import resource_dir

pytestmark = pytest.mark.emit


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


def _kernel(text, **target):
    import fractalc
    from fractalc.emit import Target, emit
    from fractalc.lower import lower
    return emit(lower(fractalc.loads(text).checked), Target(**target))


def test_each_feature_of_the_kernel_is_declared_once_and_every_block_has_one():
    """A key's feature is declared beside its field (program.py); the
    engine's `#if FEATURE_X` blocks each name one that features() gives."""
    import fractalc
    from fractalc.emit import features
    from fractalc.lower import lower
    from fractalc.program import CAMERA_KEYS, RENDER_KEYS
    from fractalc.types import keys_of
    blocks = [keys_of(key.block) for key in RENDER_KEYS.values() if key.block]
    declared = [key.feature.name for keys in (CAMERA_KEYS, RENDER_KEYS, *blocks) for key in keys.values()
                if key.feature]
    assert len(declared) == len(set(declared)) and {"DITHER", "GLOW", "PATH_TRACE", "DEPTH_OF_FIELD"} <= set(declared)
    on = features(lower(fractalc.loads("scene sphere(1)").checked))
    assert set(declared) <= set(on)
    root = resource_dir("stdlib_cl")
    text = "\n".join(path.read_text() for path in sorted(root.glob("**/*.cl")))
    assert set(re.findall(r"^#if FEATURE_(\w+)\s*$", text, re.M)) <= set(on)


def test_a_key_turns_on_its_feature_and_writes_its_constants_only_where_it_is_on():
    plain = _kernel("scene sphere(1)\nrender { dither: 0, overrelax: 1 }")
    assert "#define DITHER" not in plain and "#define OVERRELAX" not in plain and "#define GLOW_" not in plain
    assert "#define DITHER 0.5f" in _kernel("scene sphere(1)\nrender { dither: 0.5 }")
    glowing = _kernel("scene sphere(1)\nrender { glow: { strength: 2, color: (1, 0, 0) } }")
    assert "#define GLOW_STRENGTH 2.0f" in glowing and "#define GLOW_R 1.0f" in glowing
    # glow reads the plain march: the features that alter it are off, with their constants
    assert "#define OVERRELAX" not in glowing
    assert "#define GLOW_" not in _kernel("scene sphere(1)\nrender { glow: { strength: 0 } }")
    # a constant under another key's feature: bounces under the path tracer's
    assert "#define BOUNCES 3" in _kernel("scene sphere(1)\nrender { integrator: path, bounces: 3 }")
    assert "#define BOUNCES" not in _kernel("scene sphere(1)\nrender { bounces: 3 }")
    # a constant whose values the key computes, in every kernel
    assert "#define HIT_EPSILON_IS_PIXEL 1\n#define HIT_EPSILON 0.0f" in plain
    transparent = _kernel("scene sphere(1)\nrender { background: transparent, epsilon: 0.01 }")
    assert "#define HIT_EPSILON_IS_PIXEL 0\n#define HIT_EPSILON 0.01f" in transparent
    assert "#define BACKGROUND_R 0.0f" in transparent
