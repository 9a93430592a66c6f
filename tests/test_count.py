"""fractalc bench --count: the counting build counts each distance
evaluation once, for its purpose, and normal kernels hold none of it."""
import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

import fractalc
from fractalc.count import PURPOSES, count

# one pixel whose ray runs along z, `offset` to the side of the sphere's
# centre; glow keeps the scene's bound out of the march (it starts at t = 0),
# and without dither its first step is whole
SPHERE = """
scene sphere(1).translate(({offset}, 0, 0))
camera {{ position: (0, 0, -{distance}), target: (0, 0, 0), up: (0, 1, 0) }}
light directional {{ direction: (0, 0, 1), shadows: none }}
render {{ width: 1, height: 1, epsilon: {epsilon}, max_steps: 64, dither: 0, glow: {{ strength: 0.5, radius: 0.1 }} }}
"""

# every purpose but refraction's and glow's: shadows of both kinds, AO, mirrors
LIT = """
material mirror { color: (0.9, 0.9, 0.9), reflectivity: 0.5 }
scene sphere(0.8).translate((0, 0, 0.8)).material(mirror) | box(0.4).translate((1.2, 0.3, 0.4)) | plane(offset: 0)
camera { position: (0.5, -4, 2), target: (0, 0, 0.5) }
light directional { direction: (-0.5, 0.4, -1), shadows: hard }
light point { position: (2, -2, 3), intensity: 6, shadows: soft }
render { width: 16, height: 12, ao: 0.7, reflections: 1 }
"""

BULB = """
scene mandelbulb(power: 8, iterations: 12, bailout: 2)
camera { position: (0, -3.2, 1.0), target: (0, 0, 0) }
render { width: 16, height: 12 }
"""


def sphere_tracing_steps(offset: float, distance: float, epsilon: float) -> int:
    """Hart's sphere tracing of that ray, in double: evaluations until the
    distance falls below epsilon."""
    t = 0.0
    for steps in range(1, 65):
        d = math.hypot(offset, distance - t) - 1.0
        # far enough from the threshold that float's rounding agrees
        assert abs(d - epsilon) > 1e-4 * epsilon
        if d < epsilon:
            return steps
        t += d
    raise AssertionError("the ray misses")


@pytest.mark.opencl
@pytest.mark.parametrize("offset", [0.0, 0.6, 0.9])
def test_a_spheres_camera_ray_takes_the_evaluations_sphere_tracing_predicts(offset):
    distance, epsilon = 4.0, 1e-3
    counts = count(fractalc.loads(SPHERE.format(offset=offset, distance=distance, epsilon=epsilon)))
    predicted = sphere_tracing_steps(offset, distance, epsilon)
    assert predicted >= (2 if offset == 0 else 4)
    assert counts.evaluations["camera"] == predicted
    # the hit's tetrahedral normal: four more; nothing else is evaluated
    assert counts.evaluations["normals"] == 4
    assert counts.total == predicted + 4 and counts.iterations == 0


@pytest.mark.opencl
def test_counts_are_the_same_from_run_to_run_and_agree_with_the_steps_channel():
    # without the cone, whose steps are each of its rays' but one
    # evaluation for all (tests/test_cone_marching.py)
    scene = fractalc.loads(LIT.replace("render {", "render { cone_marching: off,"))
    first, second = count(scene), count(scene)
    assert first == second
    per_pixel = first.per_pixel()
    for purpose in ("camera", "normals", "shadows", "ao", "reflections"):
        assert per_pixel[purpose] > 0, purpose
    assert first.evaluations["refraction"] == first.evaluations["other"] == 0
    image = scene.render()
    assert first.evaluations["camera"] == image.steps.sum()
    hits = int((image.depth < math.inf).sum())
    # a tetrahedral normal per hit (four evaluations), and more for the mirror's hits
    assert first.evaluations["normals"] > 4 * hits
    # AO: the farthest of its five samples first, the others only where that one is occluded
    assert hits <= first.evaluations["ao"] < 5 * hits


@pytest.mark.opencl
def test_counts_are_of_rays_not_of_the_lanes_a_work_item_evaluates():
    # (without the cone, which marches a work-item's packet of rays as one)
    lit = LIT.replace("render {", "render { cone_marching: off,")
    one, many = (count(fractalc.loads(lit, lanes=lanes)) for lanes in (1, 8))
    assert one.lanes == 1 and many.lanes == 8
    assert one.evaluations == many.evaluations


@pytest.mark.opencl
def test_ambient_occlusion_of_an_open_surface_takes_one_evaluation():
    # the farthest AO sample of a plane seen from above is open: the nearer
    # ones are not taken, and the occlusion is none
    text = """
        scene plane(offset: 0)
        camera { position: (0, -3, 2), target: (0, 0, 0) }
        light directional { direction: (0, 0, -1), shadows: none }
        render { width: 16, height: 12, ao: 1, dither: 0 }
        """
    scene = fractalc.loads(text)
    counts, image = count(scene), scene.render(aovs=("ao",))
    hits = int(np.isfinite(image.depth).sum())
    assert hits > 0 and counts.evaluations["ao"] == hits
    assert np.all(image.passes["ao"][np.isfinite(image.depth)] == 1.0)


def shadow_steps(height: float, sine: float, threshold: float, reach: float, factor: float) -> int:
    """Evaluations of a shadow ray leaving a plane from `height` above it
    toward a light at elevation asin(sine), stepping `factor` times the
    distance (it only grows along this ray: no step overshoots)."""
    t, lifted, steps = 2 * threshold, height + 2 * threshold, 0
    while t < reach:
        steps += 1
        t += factor * max(lifted + t * sine, threshold)
    return steps


@pytest.mark.opencl
def test_a_shadow_ray_leaving_a_plane_takes_the_over_relaxed_steps():
    # one pixel looking down at the ground, the light 30 degrees above it
    scene = fractalc.loads("""
        scene plane(offset: 0)
        camera { position: (0, -2, 2), target: (0, 0, 0) }
        light directional { direction: (0, -0.8660254037844386, -0.5), shadows: hard }
        render { width: 1, height: 1, epsilon: 0.001, max_distance: 5, dither: 0 }
        """)
    counts, image = count(scene), scene.render()
    height = 2 - float(image.depth[0, 0]) / math.sqrt(2)     # of the hit, below the threshold
    assert 0 <= height < 1e-3
    relaxed, plain = (shadow_steps(height, 0.5, 1e-3, 5.0, factor) for factor in (1.6, 1.0))
    assert counts.evaluations["shadows"] == relaxed < plain
    assert image.rgba[0, 0, 0] > 0.5       # lit


@pytest.mark.opencl
def test_formula_iterations_are_counted_for_the_rays_evaluated():
    counts = count(fractalc.loads(BULB))
    per_evaluation = counts.iterations / counts.total
    # most evaluations are far from the bulb, where it escapes in a few
    # iterations or is not iterated at all (outside its bounding sphere)
    assert 0.5 < per_evaluation < 12


def test_normal_kernels_hold_no_counting_code():
    for text in (LIT, BULB):
        scene = fractalc.loads(text)
        for lanes in (1, 8):
            source = scene.kernel_source(lanes=lanes)
            assert not re.search(r"\bcount_\w+\(|COUNT_|\bscoped\(|march_purpose", source)
            # the params stay in constant memory: the prelude's address space, never the counting build's
            assert "#define PARAMS_SPACE __constant" in source and "PARAMS_SPACE scalar *params" in source
            assert "PARAMS_SPACE __global" not in source and "#undef PARAMS_SPACE" not in source


def test_the_counting_build_is_emitted_with_params_in_global_memory():
    """No edit of the emitted text: count.cl, after the prelude, redefines
    the params' address space; its counters start after the derived slots."""
    from fractalc.emit import Target, emit
    from fractalc.hoist import DERIVED_SLOTS
    from fractalc.lower import lower
    scene = fractalc.loads(BULB)
    source = emit(lower(scene.checked), Target(lanes=8, count=True))
    prelude, counting = source.index("#define PARAMS_SPACE __constant"), source.index("#define PARAMS_SPACE __global")
    assert prelude < counting < source.index("PARAMS_SPACE scalar *params")
    assert f"#define COUNT_BASE {len(scene.checked.params) + DERIVED_SLOTS}" in source


@pytest.mark.opencl
def test_path_traced_bounces_and_light_rays_count_as_reflections_and_shadows():
    """The path tracer's rays count under their purposes: its bounces as
    reflections, its rays toward lights and the sky as shadows; the camera's
    rays are the same work however many bounces follow."""
    text = LIT.replace("reflections: 1", "integrator: path, samples: 2, bounces: BOUNCES")
    counts = {b: count(fractalc.loads(text.replace("BOUNCES", str(b)))).evaluations for b in (1, 3)}
    # one bounce: the direction scattered at the first hit, marched
    assert counts[1]["reflections"] > 0 and counts[3]["reflections"] > counts[1]["reflections"], counts
    assert counts[1]["shadows"] > 0 and counts[3]["shadows"] > counts[1]["shadows"], counts
    assert counts[1]["camera"] == counts[3]["camera"], counts


@pytest.mark.opencl
def test_every_evaluation_in_the_counting_build_is_counted():
    scene = fractalc.loads(LIT.replace("reflectivity: 0.5", "reflectivity: 0.5, transparency: 0.5"))
    from dataclasses import replace
    from fractalc.emit import emit
    from fractalc.lower import lower
    target = replace(scene.renderer().target, count=True)
    source = emit(lower(scene.checked), target)
    code = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith("//"))
    functions = re.split(r"\n(?=\S)", code)
    evaluating = [f for f in functions if "distance_estimate(" in f.split("{", 1)[-1]
                  and not f.startswith(("real distance_estimate(", "__kernel VECTOR_LANES_HINT void distance_at_points("))]
    assert len(evaluating) >= 6       # march, normals, AO, both shadows, refraction
    for function in evaluating:
        assert "COUNT_EVALUATIONS(" in function, function.split("\n", 1)[0]


@pytest.mark.opencl
def test_bench_count_prints_and_writes_the_counts(tmp_path):
    scene_file = tmp_path / "scene.frac"
    scene_file.write_text(LIT)
    out = tmp_path / "counts.json"
    result = subprocess.run([sys.executable, "-m", "fractalc", "bench", "--count", str(scene_file),
                             "--width", "8", "--height", "6", "--frames", "2", "--json", str(out)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    figures = json.loads(out.read_text())
    assert (figures["width"], figures["height"]) == (8, 6)
    assert set(figures["by_purpose_per_pixel"]) == set(PURPOSES)
    assert math.isclose(figures["evaluations_per_pixel"], sum(figures["by_purpose_per_pixel"].values()))
    assert f"{figures['evaluations_per_pixel']:.2f}" in result.stdout
    # beside them, evaluations per second of the normal kernel's render of that view
    total = figures["evaluations_per_pixel"] * 8 * 6
    assert figures["frame_seconds"] > 0
    assert math.isclose(figures["evaluations_per_second"], total / figures["frame_seconds"], rel_tol=1e-9)
    assert f"{figures['evaluations_per_second'] / 1e6:.2f} M" in result.stdout
    refused = subprocess.run([sys.executable, "-m", "fractalc", "bench", "--count", "--sweep", str(scene_file)],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "--count" in refused.stderr
