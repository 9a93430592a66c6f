"""Cone marching (render key `cone_marching`, on by default): a
work-item's packet of camera rays is marched as one cone first, the cones
of up to LANES packets (neighbouring blocks' centre rays, or one block's
samples) side by side, a packet a lane of one vector evaluation
(stdlib_cl/engine/cone.cl). The images it leaves are tested on the hard
cases (tests/hard/test_hard.py); here: a packet's cone does not depend on
the packets marched beside it, it is in a kernel only where it is used,
and it saves evaluations."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fractalc
from fractalc import run
from fractalc.count import count
from fractalc.emit import Target, emit
from fractalc.lower import lower

# CSG, a transform, a built-in fractal with a parameter and a hybrid of
# library formulas
SCENE = """
param power = 7 in [2, 16]
let blend = union(sphere(0.5).translate((2.2, 0, 0)), box(0.4).twist(0.8).translate((2.2, 0.4, 0)), smooth: 0.2)
scene union(fractal(hybrid(bulb() * 2, amazing_box(scale: -1.5)), iterations: 10, bound: 4),
            mandelbulb(power: power).translate((0, 2.4, 0)), blend)
camera { position: (0, -7, 3), target: (0.5, 0.5, 0), fov: 50 }
render { width: 48, height: 36, dither: 0 }
"""


# a scene whose estimates are distance bounds (the hybrid above overshoots
# without its step factor): the rays hit where they would without the cone
BOUNDED = """
scene union(mandelbulb(), sphere(0.6).translate((1.8, 0, 0)))
camera { position: (0.4, -3.6, 1.2), target: (0.4, 0, 0), fov: 45 }
render { width: 48, height: 36, dither: 0, cone_marching: CONE }
"""


def kernel_source(scene, lanes: int, double: bool = False, **render_keys) -> str:
    checked = replace(scene.checked, render=replace(scene.checked.render, **render_keys))
    return emit(lower(checked), Target(lanes=lanes, double=double))


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("samples", [1, 20])
def test_a_packet_s_cone_does_not_depend_on_the_packets_beside_it(precision, samples, monkeypatch):
    # a launch one block wide marches each block's cone alone, a whole row
    # marches 12 side by side (a block's 20 samples: 16, then 4, either way)
    scene = fractalc.loads(BOUNDED.replace("CONE", "on"), precision=precision, lanes=16)
    together = scene.render(samples=samples, progress=False)
    monkeypatch.setattr(run, "TILE_WIDTH", 4)
    alone = scene.render(samples=samples, progress=False)
    assert np.isfinite(together.rgba).all() and together.rgba[..., 3].mean() > 0.2
    np.testing.assert_array_equal(alone.rgba, together.rgba)
    np.testing.assert_array_equal(alone.steps, together.steps)


@pytest.mark.opencl
def test_the_cones_of_a_block_s_samples_leave_the_hits_of_plain_marching():
    # 20 samples: cones side by side in a batch of 16 and one of 4
    scenes = {cone: fractalc.loads(BOUNDED.replace("CONE", cone), lanes=16) for cone in ("on", "off")}
    images = {cone: scenes[cone].render(samples=20, progress=False) for cone in scenes}
    coverage = {cone: images[cone].rgba[..., 3] for cone in images}
    # a pixel's coverage is its 20 samples' hits: a cone that let rays pass
    # a surface would lower it by 1/20 a ray; a cone starts its rays a
    # little apart from plain marching's, so a grazing ray may hit or miss
    # (here 36 pixels of 1728 by one sample, 8 by two)
    assert 0.2 < coverage["on"].mean() < 0.8
    assert abs(coverage["on"].mean() - coverage["off"].mean()) < 0.002
    assert (np.abs(coverage["on"] - coverage["off"]) > 0.075).mean() < 0.01


def test_the_cone_is_in_a_kernel_only_where_it_is_marched():
    scene = fractalc.loads(SCENE)
    assert "march_cones" in kernel_source(scene, 16)
    # the cones evaluate the scene's own estimate: no copy of it in scalar types
    assert "uniform_distance_estimate" not in kernel_source(scene, 16)
    assert "march_cones" not in kernel_source(scene, 1), "one ray per work-item: no packet"
    assert "march_cones" not in kernel_source(scene, 16, cone_marching="off")
    # glow reads each ray's closest approach, which the cone would skip
    glowing = fractalc.loads(SCENE.replace("dither: 0", "dither: 0, glow: { strength: 0.5, radius: 0.1 }"))
    assert "march_cones" not in kernel_source(glowing, 16)


@pytest.mark.opencl
def test_the_cone_saves_camera_evaluations():
    scenes = {cone: fractalc.loads(BOUNDED.replace("CONE", cone), lanes=16) for cone in ("on", "off")}
    on, off = (count(scenes[cone]) for cone in ("on", "off"))
    assert on.evaluations["camera"] < 0.8 * off.evaluations["camera"], (on.evaluations, off.evaluations)
    # a cone step is a march step of each of its rays, one evaluation for all
    assert on.evaluations["camera"] < 0.8 * scenes["on"].render().steps.sum()
    # the rest of the render is unchanged work: the same hits get normals
    assert on.evaluations["normals"] == pytest.approx(off.evaluations["normals"], rel=0.02)
