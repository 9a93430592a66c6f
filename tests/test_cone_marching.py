"""Cone marching (render key `cone_marching`, on by default): a work-item's
packet of camera rays is marched as one cone first, its distance evaluated
at one point with the scene's estimate in scalar types
(`uniform_distance_estimate`, emit._uniform_copy). The images it leaves are
tested on the hard cases (tests/hard/test_hard.py); here: the scalar copy
computes what the per-ray estimate does, it is in a kernel only where it is
used, and it saves evaluations."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pyopencl as cl
import pytest

import fractalc
from fractalc.count import count
from fractalc.emit import Target, double_literals, emit
from fractalc.lower import lower

# CSG, a transform, a built-in fractal with a parameter and a hybrid of
# library formulas: every kind of code the scalar copy is made from
SCENE = """
param power = 7 in [2, 16]
let blend = union(sphere(0.5).translate((2.2, 0, 0)), box(0.4).twist(0.8).translate((2.2, 0.4, 0)), smooth: 0.2)
scene union(fractal(hybrid(bulb() * 2, amazing_box(scale: -1.5)), iterations: 10, bound: 4),
            mandelbulb(power: power).translate((0, 2.4, 0)), blend)
camera { position: (0, -7, 3), target: (0.5, 0.5, 0), fov: 50 }
render { width: 48, height: 36, dither: 0 }
"""

UNIFORM_KERNEL = """
__kernel VECTOR_LANES_HINT void uniform_at_points(__global const scalar *points, __global scalar *distances,
                                __constant scalar *params, int count) {
    int i = get_global_id(0);
    distances[i] = uniform_distance_estimate(uniform_v3(points[i], points[i + count], points[i + 2 * count]),
                                             params);
}
"""


def kernel_source(scene, lanes: int, double: bool = False, **render_keys) -> str:
    checked = replace(scene.checked, render=replace(scene.checked.render, **render_keys))
    return emit(lower(checked), Target(lanes=lanes, double=double))


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
def test_the_scalar_copy_of_the_estimate_agrees_with_the_per_ray_one(precision):
    scene = fractalc.loads(SCENE, precision=precision, lanes=8)
    double = precision == "double"
    source = kernel_source(scene, 8, double) + (double_literals(UNIFORM_KERNEL) if double else UNIFORM_KERNEL)
    program = cl.Program(scene.device.context, source).build()
    rng = np.random.default_rng(7)
    points = np.concatenate([rng.uniform(-3, 3, (4000, 3)), rng.normal(0, 0.7, (4000, 3)),
                             [[0, 0, 0], [0, 2.4, 0], [2.2, 0, 0], [1e6, 0, 0], [0, 0, 1e-20]]])
    dtype = np.float64 if double else np.float32
    planar = np.ascontiguousarray(points.T, dtype=dtype)
    flags = cl.mem_flags
    queue = scene.device.queue
    points_buffer = cl.Buffer(scene.device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=planar)
    params = np.array([7.0], dtype=dtype)
    params_buffer = cl.Buffer(scene.device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=params)
    out = np.empty(len(points), dtype=dtype)
    out_buffer = cl.Buffer(scene.device.context, flags.WRITE_ONLY, out.nbytes)
    cl.Kernel(program, "uniform_at_points")(queue, (len(points),), None, points_buffer, out_buffer,
                                            params_buffer, np.int32(len(points)))
    cl.enqueue_copy(queue, out, out_buffer)
    per_ray = scene.distance(points)
    assert np.isfinite(out).all()
    # scalar and vector maths libraries may round differently in the last place
    tolerance = 1e-12 if double else 1e-5
    assert np.allclose(out, per_ray, rtol=tolerance, atol=tolerance), np.abs(out - per_ray).max()


def test_the_scalar_copy_is_in_a_kernel_only_where_the_cone_is_marched():
    scene = fractalc.loads(SCENE)
    assert "uniform_distance_estimate" in kernel_source(scene, 16)
    assert "uniform_distance_estimate" not in kernel_source(scene, 1), "one ray per work-item: no packet"
    assert "uniform_distance_estimate" not in kernel_source(scene, 16, cone_marching="off")
    # glow reads each ray's closest approach, which the cone would skip
    glowing = fractalc.loads(SCENE.replace("dither: 0", "dither: 0, glow: { strength: 0.5, radius: 0.1 }"))
    assert "uniform_distance_estimate" not in kernel_source(glowing, 16)


# a scene whose estimates are distance bounds (the hybrid above overshoots
# without its step factor): the rays hit where they would without the cone
BOUNDED = """
scene union(mandelbulb(), sphere(0.6).translate((1.8, 0, 0)))
camera { position: (0.4, -3.6, 1.2), target: (0.4, 0, 0), fov: 45 }
render { width: 48, height: 36, dither: 0, cone_marching: CONE }
"""


@pytest.mark.opencl
def test_the_cone_saves_camera_evaluations():
    scenes = {cone: fractalc.loads(BOUNDED.replace("CONE", cone), lanes=16) for cone in ("on", "off")}
    on, off = (count(scenes[cone]) for cone in ("on", "off"))
    assert on.evaluations["camera"] < 0.8 * off.evaluations["camera"], (on.evaluations, off.evaluations)
    # a cone step is a march step of each of its rays, one evaluation for all
    assert on.evaluations["camera"] < 0.8 * scenes["on"].render().steps.sum()
    # the rest of the render is unchanged work: the same hits get normals
    assert on.evaluations["normals"] == pytest.approx(off.evaluations["normals"], rel=0.02)
