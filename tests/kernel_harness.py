"""An IR expression of the point compiled on its own (the prelude and one
generated function) and evaluated at points on the OpenCL device."""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from fractalc.emit import double_literals, function_source

_KERNEL = """
__kernel VECTOR_LANES_HINT void run(__global const scalar *x, __global const scalar *y, __global const scalar *z,
                  __constant scalar *params, __global scalar *out) {
    int i = get_global_id(0);
    STORE_LANES(f(v3(LOAD_LANES(i, x), LOAD_LANES(i, y), LOAD_LANES(i, z)), params), i, out);
}
"""


@lru_cache(maxsize=None)
def _built(source: str):
    import pyopencl as cl
    import fractalc
    return cl.Program(fractalc.loads("scene sphere(1)").device.context, source).build()


def evaluate_in_kernel(expression, points, precision: str, lanes: int, params=(0.0,)) -> np.ndarray:
    """`expression` (IR of the point) at (N, 3) `points`, N a multiple of `lanes`."""
    import pyopencl as cl
    import fractalc
    from fractalc.stdlib import library
    source = "\n".join([
        f"#define LANES {lanes}", f"#define PRECISION_DOUBLE {int(precision == 'double')}", "#define FAST_MATH 0",
        library().prelude, function_source(expression, "real f(vec3 p, __constant scalar *params)"), _KERNEL])
    if precision == "double":
        source = double_literals(source)
    device = fractalc.loads("scene sphere(1)").device
    program = _built(source)
    dtype = np.float64 if precision == "double" else np.float32
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    buffers = [cl.Buffer(device.context, flags, hostbuf=np.ascontiguousarray(points[:, k], dtype=dtype))
               for k in range(3)]
    out = np.empty(len(points), dtype)
    out_buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.run(device.queue, (len(points) // lanes,), None, *buffers,
                cl.Buffer(device.context, flags, hostbuf=np.asarray(params, dtype)), out_buffer)
    cl.enqueue_copy(device.queue, out, out_buffer)
    return out.astype(np.float64)
