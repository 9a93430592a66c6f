// The types every library function is written in, so that one source serves
// one ray per work-item (LANES 1, GPUs) and one ray per vector lane (LANES
// 8/16, CPUs), in float or double. The emitter defines LANES and
// PRECISION_DOUBLE above this file.
//   scalar   a uniform number (params, camera): float or double
//   real     a number per ray: scalar, or a vector of LANES scalars
//   mask     a per-ray truth value (comparison result): int, int8, long8, ...
//   lane_int a per-ray integer of the mask's width
//   vec3     a point or direction per ray (three reals)
#define CONCAT_(a, b) a##b
#define CONCAT(a, b) CONCAT_(a, b)

#if PRECISION_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double scalar;
#define SCALAR_NAME double
#define MASK_ELEMENT long
#define SCALAR_MIN_EPSILON 1e-12
#else
typedef float scalar;
#define SCALAR_NAME float
#define MASK_ELEMENT int
#define SCALAR_MIN_EPSILON 1e-6f
#endif

#if LANES == 1
typedef scalar real;
typedef int mask;
typedef int lane_int;
typedef uint lane_uint;
#define MASK_TRUE 1
#define ANY(m) (m)
#define ALL(m) (m)
#define SELECT(if_false, if_true, m) ((m) ? (if_true) : (if_false))
#define TO_REAL(x) ((real)(x))
#define TO_FLOAT(x) ((float)(x))
#define TO_UINT(x) ((uint)(x))
#define LOAD_LANES(i, ptr) ((ptr)[i])
#define STORE_LANES(v, i, ptr) ((ptr)[i] = (v))
typedef float lane_float;
#define VECTOR_LANES_HINT
#else
#define REAL_TYPE CONCAT(SCALAR_NAME, LANES)
typedef REAL_TYPE real;
typedef CONCAT(MASK_ELEMENT, LANES) mask;
typedef mask lane_int;
typedef CONCAT(uint, LANES) lane_uint;
#define MASK_TRUE ((mask)(-1))
// Whether any (all) lanes are set, as the mask's halves or-ed (and-ed)
// together down to one lane: a few vector operations and one branch, where
// PoCL's any() tests the lanes' sign bits a pair at a time, a branch each,
// on the iteration's path (bulb-640 6% faster there, 1% on Intel's
// runtime). A set lane is -1, so the folded lane is negative.
// Only the widths up to the kernel's: a wider vector's overload would be
// dead code, and a 16-lane long argument on a CPU without AVX-512 makes
// PoCL warn of its calling convention.
#define FOLD_OF(width) \
    __attribute__((overloadable)) int any_lane(CONCAT(MASK_ELEMENT, width) m) { return any_lane(m.lo | m.hi); } \
    __attribute__((overloadable)) int all_lanes(CONCAT(MASK_ELEMENT, width) m) { return all_lanes(m.lo & m.hi); }
__attribute__((overloadable)) int any_lane(CONCAT(MASK_ELEMENT, 2) m) { return (m.x | m.y) < 0; }
__attribute__((overloadable)) int all_lanes(CONCAT(MASK_ELEMENT, 2) m) { return (m.x & m.y) < 0; }
#if LANES >= 4
FOLD_OF(4)
#endif
#if LANES >= 8
FOLD_OF(8)
#endif
#if LANES >= 16
FOLD_OF(16)
#endif
#undef FOLD_OF
#define ANY(m) any_lane(m)
#define ALL(m) all_lanes(m)
#define SELECT(if_false, if_true, m) select((if_false), (if_true), (m))
#define TO_REAL(x) CONCAT(convert_, REAL_TYPE)(x)
#define TO_FLOAT(x) CONCAT(convert_float, LANES)(x)
#define TO_UINT(x) CONCAT(convert_uint, LANES)(x)
#define LOAD_LANES(i, ptr) CONCAT(vload, LANES)((i), (ptr))
#define STORE_LANES(v, i, ptr) CONCAT(vstore, LANES)((v), (i), (ptr))
typedef CONCAT(float, LANES) lane_float;
// On a kernel: its work-items already hold LANES rays in vectors. Intel's
// CPU compiler would otherwise vectorize them again across work-items: 4x
// the build time for the same speed (docs/drivers.md); PoCL ignores it.
#define VECTOR_LANES_HINT __attribute__((vec_type_hint(real)))
#endif

#if FAST_MATH
// Faster, less exact transcendental functions (render key fast_math; the
// speed/error sweep of `fractalc bench --sweep` measures what they cost).
// (#undef first: some drivers' headers define these names as macros)
#undef sin
#undef cos
#undef exp
#undef log
#undef sqrt
#undef rsqrt
#undef sincos
#define sin native_sin
#define cos native_cos
#define exp native_exp
#define log native_log
#define sqrt native_sqrt
#define rsqrt native_rsqrt
#define sincos(x, cosine) (*(cosine) = native_cos(x), native_sin(x))
#endif

#if REFINED_RSQRT
// 1 / sqrt(x) as the hardware's estimate refined by one Newton step, its
// residual 1 - x r^2 and the step fused (1 ulp from the exact value; 2 as
// r (1.5 - 0.5 x r^2)), in float kernels for drivers whose exact rsqrt is
// a library call, around which a loop keeps its vectors in memory (Intel's
// CPU runtime: bulb-640 4.6% faster; fractalc/devices.py refines_rsqrt).
// At x = 0 and x = inf the estimate is exact (inf, 0) and the residual NaN.
#define REFINED_RSQRT_OF(type) __attribute__((overloadable)) type refined_rsqrt(type x) { \
        type r = native_rsqrt(x); \
        type residual = fma(-x * r, r, (type)1.0f); \
        return select(fma(0.5f * r, residual, r), r, isnan(residual)); \
    }
REFINED_RSQRT_OF(float)
#if LANES > 1
REFINED_RSQRT_OF(real)
#endif
#undef rsqrt
#define rsqrt refined_rsqrt
#endif

// A function every caller takes in whole: the scene's distance estimate
// (PoCL 3.1 otherwise calls it, passing its lanes through memory: 6% of
// bulb-640's frame; docs/performance.md)
#define ALWAYS_INLINE __attribute__((always_inline))
// A function called once per many rays whose inlined body (an estimate of
// its own) would only lengthen the build: cone marching's (bulb-640's
// build on Intel's runtime 1.33 s inlined, 1.08 s not; its frame the same)
#define NEVER_INLINE __attribute__((noinline))

// The params buffer's address space: the counting build (count.cl) makes it
// __global, for the counters that follow the params there
#define PARAMS_SPACE __constant

typedef struct { real x, y, z; } vec3;

vec3 v3(real x, real y, real z) { vec3 v = { x, y, z }; return v; }
vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
vec3 v3_mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
vec3 v3_scale(vec3 a, real s) { return v3(a.x * s, a.y * s, a.z * s); }
vec3 v3_abs(vec3 a) { return v3(fabs(a.x), fabs(a.y), fabs(a.z)); }
real v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
real v3_length(vec3 a) { return sqrt(v3_dot(a, a)); }
vec3 v3_normalize(vec3 a) { return v3_scale(a, rsqrt(max(v3_dot(a, a), (real)1e-30f))); }
vec3 v3_select(vec3 if_false, vec3 if_true, mask m) {
    return v3(SELECT(if_false.x, if_true.x, m), SELECT(if_false.y, if_true.y, m),
              SELECT(if_false.z, if_true.z, m));
}
