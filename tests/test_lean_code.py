"""The generated code is lean: values computed from params alone are
derived params (fractalc/hoist.py), computed once per launch, never per
estimate or per iteration."""
import re

import numpy as np
import pytest

import fractalc
from fractalc import ir, ranges
from fractalc.devices import DeviceInfo, build_options
from fractalc.emit import Target, emit, emit_distance
from fractalc.lower import lower

pytestmark = pytest.mark.emit

BULB = """
param power = 8 in [2, 16]
param angle = 30 in [0, 90]
scene mandelbulb(power: power, iterations: 12, bailout: 2).rotate((0, 0, 1), angle * 2)
render { width: 64, height: 48 }
"""


def _function(source: str, name: str) -> str:
    """The text of the C function `name` (its signature to its closing brace)."""
    found = re.search(rf"^(\w+ )*{name}\(.*?^}}", source, re.M | re.S)
    assert found, name
    return found.group(0)


@pytest.mark.parametrize("lanes", [1, 8])
def test_param_only_values_leave_the_estimate(lanes):
    source = fractalc.loads(BULB).kernel_source(lanes=lanes)
    # the same scene with the angle written in: its rotation's sine and cosine are constants
    folded = fractalc.loads(BULB.replace("angle * 2", "60")).kernel_source(lanes=lanes)
    body = _function(source, "distance_estimate")
    # the bound radius pow(2, 1 / (power - 1)) and the rotation's trigonometry
    assert not re.search(r"\b(pow|\w*bound_radius)\(", body), body
    trigonometry = re.compile(r"\b(sin|cos)\(")
    assert len(trigonometry.findall(body)) == len(trigonometry.findall(_function(folded, "distance_estimate")))
    kernel = _function(source, "__kernel void derived_params")
    assert re.search(r"\b\w*mandelbulb_bound_radius\(", kernel)
    assert re.search(r"\b(sin|cos)\(", kernel)


@pytest.mark.parametrize("lanes", [1, 8])
def test_the_estimate_computes_no_value_it_does_not_read(lanes):
    # the power-8 step promises |z^8| <= 2 r^8 + 1 to the range analysis
    # (`within`): the promise's bounds are read there, not computed
    body = _function(fractalc.loads(BULB).kernel_source(lanes=lanes), "distance_estimate")
    temporaries = re.findall(r"\b(?:real|scalar|mask|lane_int|int) ([a-z]\d+) = ", body)
    assert temporaries, body
    for temporary in temporaries:
        assert len(re.findall(rf"\b{temporary}\b", body)) > 1, (temporary, body)


@pytest.mark.parametrize("lanes", [1, 8])
def test_the_scene_bound_and_the_shading_compute_no_power(lanes):
    # the bound radius pow(2, 1 / (power - 1)) is the estimate's derived
    # param; Blinn-Phong's highlight is exp2 of a log2 (PoCL's pow costs
    # ten times as much)
    source = fractalc.loads(BULB + "light directional { direction: (0, 0, -1) }").kernel_source(lanes=lanes)
    kernel = source[:source.index("__kernel void derived_params")] + source[source.index("uvec3;"):]
    assert "pow(" not in re.sub(r"^scalar uniform_\w+\(.*?^}", "", kernel, flags=re.M | re.S)
    bound = _function(source, "scene_bound")
    assert re.search(r"return \(real\)params\[\d+\];", bound), bound


def test_the_estimate_is_inlined_into_its_callers():
    # PoCL calls it otherwise, its vectors passed through memory
    source = fractalc.loads(BULB).kernel_source(lanes=8)
    assert re.search(r"^ALWAYS_INLINE real distance_estimate\(", source, re.M)
    assert "#define ALWAYS_INLINE __attribute__((always_inline))" in source


@pytest.mark.parametrize("lanes", [1, 8])
def test_the_bailout_test_takes_no_square_root(lanes):
    # |z|^2 against bailout^2: the loop's test waits for no square root, and
    # the iteration that stops computes none (the step's own |z| comes after)
    source = fractalc.loads(BULB).kernel_source(lanes=lanes)
    body = _function(source, "distance_estimate")
    loop = body[body.index("for (int "):]
    test = loop[:loop.index("break;")]
    assert "sqrt(" not in test, test
    assert re.search(r"<= 4\.0f\)", test), test
    assert "sqrt(" in loop[len(test):]


@pytest.mark.parametrize("shadows, function", [("hard", "hard_shadow"), ("soft", "soft_shadow")])
def test_a_finished_shadow_ray_evaluates_the_end_of_its_ray(shadows, function):
    # where the estimate iterates, a lane whose shadow ray is blocked would
    # otherwise evaluate where it stopped, at a surface, where the orbit
    # iterates longest and keeps the loop going for the lanes still
    # marching; without iterations the select would only cost
    light = f"light directional {{ direction: (0, 0, -1), shadows: {shadows} }}"
    for scene, sample in ((BULB, "SELECT(max_t, t, active)"), ("scene sphere() | plane(offset: -1)\n", "t")):
        source = fractalc.loads(scene + light).kernel_source(lanes=8)
        calls = re.findall(r"distance_estimate\((.*?), params\)", _function(source, function))
        assert calls and all("shadow_sample_t(t, max_t, active)" in call for call in calls), calls
        assert f"return {sample};" in _function(source, "shadow_sample_t")


def test_distance_program_hoists_too():
    scene = fractalc.loads(BULB)
    source = emit_distance(lower(scene.checked), Target(lanes=8))
    assert not re.search(r"\b(pow|\w*bound_radius)\(", _function(source, "distance_estimate"))
    assert "__kernel void derived_params" in source


@pytest.mark.opencl
def test_derived_params_follow_the_params():
    # the derived values are computed again for new param values: the
    # distances equal those of the scene with the values written in
    scene = fractalc.loads(BULB)
    points = np.random.default_rng(3).uniform(-1.3, 1.3, (64, 3))
    for power, angle in ((8, 30), (3.5, 70)):
        scene.set_params({"power": power, "angle": angle})
        literal = fractalc.loads(BULB.replace("power: power", f"power: {power}").replace("angle * 2", f"{angle * 2}"))
        assert np.allclose(scene.distance(points), literal.distance(points), rtol=1e-5, atol=1e-6)


GUARDED = """
param power = 8 in [2, 16]
param bailout = 2 in [1, BAILOUT_HIGH]
scene mandelbulb(power: power, iterations: 12, bailout: BAILOUT)
render { width: 64, height: 48 }
"""
OVERFLOW_TEST = re.compile(r"<= 1e\+36f\)")      # |z|^2 <= OVERFLOW_LENGTH^2, the overflow guard
ESCAPE_TEST = re.compile(r"1000000000000\.0f <")   # r^power > 1e12: the formula's own overflow branch


@pytest.mark.parametrize("bailout, high, guarded", [
    ("2", "2", False),              # |z| <= 2: |z^power + c|^2 stays below 1e11
    ("1e6", "2", True),             # |z| up to 1e6: z^8 overflows past 1e36
    ("bailout", "2", False),        # a param bailout within [1, 2]
    ("bailout", "1e6", True),       # a param whose range lets it overflow
])
def test_overflow_guards_only_where_they_can_fire(bailout, high, guarded):
    source = fractalc.loads(GUARDED.replace("BAILOUT_HIGH", high).replace("BAILOUT", bailout)).kernel_source(lanes=8)
    body = _function(source, "distance_estimate")
    assert bool(OVERFLOW_TEST.search(body)) == guarded
    assert bool(ESCAPE_TEST.search(body)) == guarded
    # the stopped flag goes with them: the loop's test is the bailout's alone
    assert bool(re.search(r"a0 = a0 & \(\(!s\d+\) & ", body)) == guarded
    # and the clamp of the final estimate: with |z| bounded and the log's
    # argument kept within [1e-30, 1e18], 0.5 ln(r) r / dr cannot leave +-1e30
    final = [line for line in body.splitlines() if "log(" in line][-1]
    assert bool(re.search(r"clamp\(", final)) == guarded, final


def test_the_analysis_keeps_what_can_happen():
    x, y = ir.Comp(ir.Var("p", ir.VEC3), 0), ir.Comp(ir.Var("p", ir.VEC3), 1)
    wave = ir.op("sin", x)
    (kept,) = ranges.simplify((ir.op("min", wave, ir.const(0.5)),), {})
    assert kept.op == "min_of_numbers"                  # sin reaches above 0.5, and is never NaN
    (dropped,) = ranges.simplify((ir.op("min", wave, ir.const(2.0)),), {})
    assert dropped is wave
    # a clamp guards a NaN: 0 / 0 where y = 0
    ratio = ir.div(x, y)
    (nan_aware,) = ranges.simplify((ir.op("max", ratio, ir.const(0.0)),), {})
    assert nan_aware.op == "max"                        # fmax, which takes the 0 where the ratio is NaN
    (guard,) = ranges.simplify((ir.op("clamp", ir.op("sin", ratio), ir.const(-1.0), ir.const(1.0)),), {})
    assert guard.op == "clamp"
    # a param's declared range decides a comparison of it, or leaves it
    power = ir.Param(0, "power")
    chosen = ir.op("select", ir.op("lt", ir.mul(power, wave), ir.const(20.0)), x, y)
    assert ranges.simplify((chosen,), {0: (2.0, 16.0)}) == (x,)
    assert ranges.simplify((chosen,), {0: (2.0, 32.0)}) == (chosen,)


@pytest.mark.parametrize("n, products", [(2, 1), (8, 3), (32, 5), (7, 4)])
def test_whole_powers_are_products(n, products):
    x = ir.Comp(ir.Var("p", ir.VEC3), 0)
    power = ir.op("pow", x, ir.const(n))
    nodes = [node for node in ir.walk(power) if isinstance(node, ir.Op)]
    assert {node.op for node in nodes} == {"*"} and len(nodes) == products
    points = np.array([[1.1, 0, 0], [-1.3, 0, 0], [0, 0, 0]])
    assert np.allclose(ir.evaluate_at((power,), points)[0], points[:, 0] ** n, rtol=1e-14)
    assert ir.op("pow", x, ir.const(2.5)).op == "pow"


def test_carries_that_never_change_are_not_carried():
    x = ir.Comp(ir.Var("p", ir.VEC3), 0)
    z, offset, limit = ir.State(0, 0), ir.State(0, 1), ir.State(0, 2)
    # z = z^2 + x while |z| < limit; the offset keeps its start, the limit is set to its start again
    loop = ir.Loop(0, (x, ir.const(0.25), ir.const(2.0)), (ir.op("+", ir.mul(z, z), x), offset, ir.const(2.0)),
                   ir.op("lt", ir.op("abs", z), limit), ir.const(6.0))
    result = ir.op("+", ir.Out(loop, 0), ir.Out(loop, 1))
    (lean,) = ir.without_idle_carries((result,))
    (carried,) = {node for node in ir.walk(lean) if isinstance(node, ir.Loop)}
    assert len(carried.init) == 1
    points = np.array([[0.1, 0, 0], [-1.5, 0, 0], [0.3, 0, 0], [1.9, 0, 0]])
    assert np.array_equal(ir.evaluate_at((lean,), points)[0], ir.evaluate_at((result,), points)[0])
    # the Mandelbulb's loop, once its guards are gone, carries z and dr alone
    body = _function(fractalc.loads(BULB).kernel_source(lanes=8), "distance_estimate")
    assert not re.search(r"\bn\d+ = s\d+;", body), body


REFINED_RSQRT_KERNEL = """
__kernel void refined(__global const float *x, __global float *out) {
    int i = get_global_id(0);
    real v = LOAD_LANES(i, x);
    STORE_LANES(rsqrt(v), i, out);
    out[LANES * get_global_size(0) + i] = rsqrt(x[i]);      // the scalar overload
}
"""


@pytest.mark.opencl
@pytest.mark.parametrize("vector", [False, True])
def test_the_refined_rsqrt_is_within_an_ulp(vector, driver):
    # Intel's runtime takes rsqrt as the hardware estimate and one fused
    # Newton step (devices.refines_rsqrt); the prelude's form builds on
    # every driver and stays within 1.5 ulp of 1 / sqrt(x), for vectors and
    # scalars alike (measured on Intel's: 1.03 ulp in vectors, 1.33 from the
    # scalar estimate's fewer bits; the unfused step's 1.9 flipped
    # knife-edge shadows in tests/hard)
    import pyopencl as cl
    from fractalc.stdlib import library
    device = fractalc.loads("scene sphere()", device=driver).device
    lanes = device.lanes if vector else 1      # the widths the driver builds (lanes.py)
    source = "\n".join([f"#define LANES {lanes}", "#define PRECISION_DOUBLE 0", "#define FAST_MATH 0",
                        "#define REFINED_RSQRT 1", library().prelude, REFINED_RSQRT_KERNEL])
    # with the options that float programs on this driver are built with
    program = cl.Program(device.context, source).build(options=list(build_options(device.info, False)))
    x = np.exp(np.random.default_rng(5).uniform(-30, 30, 4096 * lanes)).astype(np.float32)
    x[:2 * lanes:2], x[1:2 * lanes:2] = 0.0, np.inf         # exact there: inf and 0, not NaN
    out = np.empty(len(x) + len(x) // lanes, np.float32)
    flags = cl.mem_flags
    x_buffer = cl.Buffer(device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=x)
    out_buffer = cl.Buffer(device.context, flags.WRITE_ONLY, out.nbytes)
    program.refined(device.queue, (len(x) // lanes,), None, x_buffer, out_buffer)
    cl.enqueue_copy(device.queue, out, out_buffer)
    with np.errstate(divide="ignore"):
        exact = 1 / np.sqrt(x.astype(np.float64))
    for got, want in ((out[:len(x)], exact), (out[len(x):], exact[:len(x) // lanes])):
        edge = ~np.isfinite(want) | (want == 0)
        assert np.array_equal(got[edge], want[edge])
        ulps = np.abs(got[~edge] - want[~edge]) / np.spacing(want[~edge].astype(np.float32))
        assert ulps.max() < 1.5


REDUCTIONS_KERNEL = """
__kernel void reductions(__global const MASK_ELEMENT *lanes, __global int *out) {
    int i = get_global_id(0);
    mask m = LOAD_LANES(i, lanes);
    out[2 * i] = ANY(m);
    out[2 * i + 1] = ALL(m);
}
"""


@pytest.mark.opencl
@pytest.mark.parametrize("double", [False, True])
def test_any_and_all_of_every_mask(double, driver):
    # the prelude's ANY and ALL fold a mask's halves together (PoCL's any()
    # tests the lanes a pair at a time, a branch each): every pattern of the
    # driver's lanes, in float's masks (int) and double's (long)
    import pyopencl as cl
    from fractalc.stdlib import library
    device = fractalc.loads("scene sphere()", device=driver).device
    if double and not device.info.double:
        pytest.skip("no double precision")
    # every width up to the driver's (the lane probe reads ANY too: where it
    # fails, a CPU driver falls back to one ray per work-item)
    assert device.lanes > 1 or device.info.kind == "GPU"
    for lanes in (2, 4, 8, 16):
        if lanes > device.lanes:
            break
        source = "\n".join([f"#define LANES {lanes}", f"#define PRECISION_DOUBLE {int(double)}",
                            "#define FAST_MATH 0", "#define REFINED_RSQRT 0", library().prelude,
                            REDUCTIONS_KERNEL])
        program = cl.Program(device.context, source).build()
        patterns = np.arange(2 ** lanes)
        masks = -((patterns[:, None] >> np.arange(lanes)) & 1).astype(np.int64 if double else np.int32)
        out = np.empty(2 * len(patterns), np.int32)
        flags = cl.mem_flags
        mask_buffer = cl.Buffer(device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=masks)
        out_buffer = cl.Buffer(device.context, flags.WRITE_ONLY, out.nbytes)
        program.reductions(device.queue, (len(patterns),), None, mask_buffer, out_buffer)
        cl.enqueue_copy(device.queue, out, out_buffer)
        assert np.array_equal(out[0::2] != 0, patterns != 0), lanes
        assert np.array_equal(out[1::2] != 0, patterns == 2 ** lanes - 1), lanes


def test_the_power_8_step_takes_its_root_and_its_reciprocal_side_by_side():
    # rho and 1 / rho^2, each from rho^2 alone: a root and a division that
    # wait for nothing else (1 / rho as rsqrt, which PoCL computes as a root
    # and then a division, held both on the iteration's path: bulb-640 6%)
    body = _function(fractalc.loads(BULB).kernel_source(lanes=8), "distance_estimate")
    step = body[body.index("if (k"):body.index("} else {")]
    assert "rsqrt(" not in step, step
    roots = re.findall(r"\bsqrt\((r\d+)\)", step)
    divided = re.findall(r"1\.0f / f?max\((r\d+),", step)
    assert len(divided) == 1 and divided[0] in roots, step


def test_the_refined_rsqrt_is_chosen_for_float_kernels_without_native_functions():
    scene = fractalc.loads(BULB)
    lowered = lower(scene.checked)
    assert "#define REFINED_RSQRT 1" in emit(lowered, Target(lanes=8, refined_rsqrt=True))
    assert "#define REFINED_RSQRT 0" in emit(lowered, Target(lanes=8))
    # native_ functions replace it where they are exact; double has no native_rsqrt
    assert "#define REFINED_RSQRT 0" in emit(lowered, Target(lanes=8, refined_rsqrt=True, exact_native=True))
    double = lower(scene.checked.__class__(**{**scene.checked.__dict__,
                                              "render": scene.render_settings(precision="double")}))
    assert "#define REFINED_RSQRT 0" in emit(double, Target(lanes=8, double=True, refined_rsqrt=True))


def test_build_options_are_chosen_per_driver():
    # -cl-unsafe-math-optimizations for float programs on Intel's CPU
    # runtime (about 6% of bulb-640 there, the accuracy tests passing with
    # it); nothing on PoCL, where it gains nothing, nor in double
    intel = DeviceInfo(0, "AMD EPYC", "Intel(R) OpenCL", "CPU", "OpenCL 3.0", True, 2, "2026.22")
    pocl = DeviceInfo(1, "cpu", "Portable Computing Language", "CPU", "OpenCL 3.0", True, 2, "3.1",
                      "OpenCL 3.0 PoCL 3.1")
    assert build_options(intel, False) == ("-cl-unsafe-math-optimizations",)
    assert build_options(intel, True) == ()
    assert build_options(pocl, False) == ()
    # a compiled kernel says how to build it
    lowered = lower(fractalc.loads(BULB).checked)
    assert "(build with no options;" in emit(lowered, Target(lanes=8))
    assert "(build with -cl-unsafe-math-optimizations;" in emit(
        lowered, Target(lanes=8, build_options=("-cl-unsafe-math-optimizations",)))


@pytest.mark.opencl
def test_the_device_builds_with_the_options_its_kernel_names(driver, monkeypatch):
    from fractalc import api
    scene = fractalc.loads(BULB, device=driver)
    wanted = build_options(scene.device.info, False)
    assert f"(build with {' '.join(wanted) or 'no options'};" in scene.kernel_source().split("\n")[2]
    built = []
    original = api.build

    def recording(source, device, options=(), **keys):
        built.append((source, tuple(options)))
        return original(source, device, options, **keys)
    monkeypatch.setattr(api, "build", recording)
    scene.render(width=16, height=16, progress=False)
    assert (scene.kernel_source(), wanted) in built


# CSG, a transform, a built-in fractal with a param (its power-8 branch and
# the general one), a hybrid of library formulas (loops in loops) and an
# orbit trap's colour: every kind of code an estimate is written from
TWO_POINTS_SCENE = """
param power = 7 in [2, 16]
let blend = union(sphere(0.5).translate((2.2, 0, 0)), box(0.4).twist(0.8).translate((2.2, 0.4, 0)), smooth: 0.2)
scene union(fractal(hybrid(bulb() * 2, amazing_box(scale: -1.5)), iterations: 10, bound: 4),
            mandelbulb(power: power).translate((0, 2.4, 0)), blend)
"""

TWO_POINTS_KERNEL = """
__kernel VECTOR_LANES_HINT void at_two_points(__global const scalar *points, __constant scalar *params,
                                              int count, __global scalar *out) {
    int i = get_global_id(0);
    vec3 p = v3(LOAD_LANES(i, points), LOAD_LANES(i, points + count), LOAD_LANES(i, points + 2 * count));
    int j = i + get_global_size(0);
    vec3 q = v3(LOAD_LANES(j, points), LOAD_LANES(j, points + count), LOAD_LANES(j, points + 2 * count));
    real at_p, at_q;
    distance_estimates(p, q, &at_p, &at_q, params);
    STORE_LANES(at_p, i, out);
    STORE_LANES(at_q, j, out);
    STORE_LANES(distance_estimate(p, params), i, out + count);
    STORE_LANES(distance_estimate(q, params), j, out + count);
}
"""


def test_the_estimate_at_two_points_is_written_side_by_side():
    # one loop for each of the estimate's loops, one branch for each of its
    # per-ray branches, each statement once per point
    source = fractalc.loads(TWO_POINTS_SCENE).kernel_source(lanes=8)
    one, two = _function(source, "distance_estimate"), _function(source, "distance_estimates")
    assert two.count("for (") == one.count("for (") > 0
    assert two.count("if (ANY(") == one.count("if (ANY(") > 0
    assert len(re.findall(r"\bsqrt\(", two)) == 2 * len(re.findall(r"\bsqrt\(", one))
    # one ray per work-item (a GPU's): one estimate after the other
    single = _function(fractalc.loads(TWO_POINTS_SCENE).kernel_source(lanes=1), "distance_estimates")
    assert single.count("distance_estimate(") == 2 and "for (" not in single


@pytest.mark.opencl
@pytest.mark.parametrize("double", [False, True])
def test_the_estimate_at_two_points_is_the_estimate_at_each(double, driver):
    # pairs of points whose orbits end at different iterations (one escapes
    # at once while the other iterates on, one inside the bound and the
    # other outside): each point's value is the single estimate's
    import pyopencl as cl
    from fractalc.run import kernel_params
    scene = fractalc.loads(TWO_POINTS_SCENE, device=driver, precision="double" if double else "float")
    if double and not scene.device.info.double:
        pytest.skip("no double precision")
    lanes = scene.lanes_in_use
    source = emit(lower(scene.checked), Target(lanes=lanes, double=double,
                                              build_options=build_options(scene.device.info, double)))
    source += TWO_POINTS_KERNEL
    program = cl.Program(scene.device.context, source).build(options=list(build_options(scene.device.info, double)))
    rng = np.random.default_rng(3)
    near = np.concatenate([rng.normal((0, 2.4, 0), 0.6, (1024, 3)), rng.normal(0, 0.8, (1024, 3))])
    far = np.concatenate([rng.uniform(-6, 6, (1024, 3)), rng.normal((2.2, 0.2, 0), 0.4, (1024, 3))])
    points = np.concatenate([near, far[::-1]])       # p from one set, q from the other
    count = len(points)
    dtype = np.float64 if double else np.float32
    planar = np.ascontiguousarray(points.T, dtype=dtype)
    flags = cl.mem_flags
    queue = scene.device.queue
    points_buffer = cl.Buffer(scene.device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=planar)
    out = np.empty(2 * count, dtype=dtype)
    out_buffer = cl.Buffer(scene.device.context, flags.WRITE_ONLY, out.nbytes)
    program.at_two_points(queue, (count // 2 // lanes,), None, points_buffer,
                          kernel_params(program, scene.device, [7.0], double), np.int32(count), out_buffer)
    cl.enqueue_copy(queue, out, out_buffer)
    side_by_side, one_by_one = out[:count], out[count:]
    assert np.isfinite(one_by_one).all() and (one_by_one < 0).any() and (one_by_one > 0.5).any()
    # the same operations; a compiler may contract them apart (Intel's
    # runtime with its unsafe-math option, in float)
    tolerance = 1e-12 if double else 1e-5
    np.testing.assert_allclose(side_by_side, one_by_one, rtol=tolerance, atol=tolerance)
    # and the kernel above evaluates the scene's estimate with its params
    # (in float, a chaotic orbit of the hybrid may round apart in two programs)
    reference = scene.distance(points)
    assert (np.abs(one_by_one - reference) <= tolerance * (1 + np.abs(reference))).mean() > 0.99
