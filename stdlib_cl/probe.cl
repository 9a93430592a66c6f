// The lane probe (fractalc/lanes.py): the built-in functions the library
// and the generated code call, on `real` values of this build's width and
// precision, and the masked loop every march and fractal runs. A driver
// whose compiler cannot build or run one of them at this width (pip's
// PoCL 3.0 crashes on float16 sqrt on AVX-512 CPUs) fails here, in a child
// process, instead of in the user's render. Spliced after the prelude.
//
// in: `count` values x in (0, 1), then `count` values y in (0.5, 2);
// out: PROBE_RESULTS rows of `count` values, in the order of
// fractalc/lanes.py's PROBE_FUNCTIONS.

#define PROBE_RESULTS 32

#if PRECISION_DOUBLE
// OpenCL's native_ functions are float-only: in double their rows repeat
// the exact functions
#define native_sqrt sqrt
#define native_rsqrt rsqrt
#define native_sin sin
#define native_cos cos
#define native_exp exp
#define native_log log
#endif

__kernel VECTOR_LANES_HINT void probe(__global const scalar *in, __global scalar *out, int count) {
    int i = get_global_id(0);
    real x = LOAD_LANES(i, in);
    real y = LOAD_LANES(i, in + count);
    real results[PROBE_RESULTS];
    real cosine;
    results[0] = sqrt(x);
    results[1] = rsqrt(x);
    results[2] = sin(x);
    results[3] = cos(x);
    results[4] = tan(x);
    results[5] = asin(x);
    results[6] = acos(x);
    results[7] = atan(x);
    results[8] = atan2(x, y);
    results[9] = exp(x);
    results[10] = log(y);
    results[11] = pow(y, x);
    results[12] = fabs(x - 0.5f);
    results[13] = floor(4.0f * x);
    results[14] = round(4.0f * x);
    results[15] = fmin(x, y - 1.0f);
    results[16] = fmax(x, y - 1.0f);
    results[17] = min(x, y - 1.0f);
    results[18] = max(x, y - 1.0f);
    results[19] = clamp(x, (real)0.25f, (real)0.75f);
    results[20] = mix(x, y, (real)0.25f);
    results[21] = sincos(x, &cosine) + cosine;
    results[22] = SELECT(x, y, x < 0.5f);
    results[23] = ceil(4.0f * x);
    results[24] = native_sqrt(x);
    results[25] = native_rsqrt(x);
    results[26] = native_sin(x);
    results[27] = native_cos(x);
    results[28] = native_exp(x);
    results[29] = native_log(y);
    // a masked loop, as the march runs it: z -> z^2 + x until |z| > 2
    real z = 0.0f, steps = 0.0f;
    mask active = MASK_TRUE;
    for (int n = 0; n < 64; n++) {
        active = active & (fabs(z) <= 2.0f);
        if (!ANY(active)) break;
        z = SELECT(z, z * z + y, active);
        steps = SELECT(steps, steps + 1.0f, active);
    }
    results[30] = steps;
    lane_uint bits = TO_UINT(x * 1000.0f);
    results[31] = TO_REAL((bits * (uint)3u) >> 1);
    for (int k = 0; k < PROBE_RESULTS; k++)
        STORE_LANES(results[k], i, out + k * count);
}
