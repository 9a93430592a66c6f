// The counting build of `fractalc bench --count` (fractalc/count.py), placed
// after the prelude: the engine and the library call its hooks,
// COUNT_EVALUATIONS before each distance evaluation, COUNT_MARCH before a
// march, COUNT_SCOPE before a function that serves the rays of a mask (a
// normal, AO); each hook is a line of its own, which the emitter drops from
// every other kernel. The emitter writes COUNT_ITERATIONS into each loop of
// the distance estimate of this build alone. Only this build has them:
// there `params` is a __global buffer whose values are followed, from
// COUNT_BASE (a constant of the build), by COUNT_SLOTS reals (one per ray)
// per work-item. Rays are counted where they are marched (their lanes of a
// mask), not the lanes a vector evaluates along with them.
#undef PARAMS_SPACE
#define PARAMS_SPACE __global
#define COUNT_CAMERA 0
#define COUNT_NORMALS 1
#define COUNT_SHADOWS 2
#define COUNT_AO 3
#define COUNT_REFLECTIONS 4
#define COUNT_REFRACTION 5
#define COUNT_OTHER 6
#define COUNT_PURPOSES 7
// slots: the purpose the next march counts for; the rays of the evaluation
// under way (their formula iterations count); the rays a function without
// a mask of its own serves (normals, AO); a count per purpose; iterations
#define SLOT_MARCH 0
#define SLOT_EVALUATING 1
#define SLOT_SCOPE 2
#define SLOT_COUNTS 3
#define SLOT_ITERATIONS (SLOT_COUNTS + COUNT_PURPOSES)
#define COUNT_SLOTS (SLOT_ITERATIONS + 1)
// the hooks, in the calling function's `params`
#define COUNT_EVALUATIONS(purpose, rays, each) count_evaluations(purpose, rays, each, params)
#define COUNT_MARCH(purpose) count_march_purpose(purpose, params)
#define COUNT_SCOPE(rays) count_scope(rays, params)
#define COUNT_ITERATIONS(rays) count_iterations(rays, params)

__global scalar *count_slots(__global scalar *params) {
    size_t item = get_global_id(1) * get_global_size(0) + get_global_id(0);
    return params + COUNT_BASE + item * (COUNT_SLOTS * LANES);
}

real count_load(int slot, __global scalar *params) {
    return LOAD_LANES(slot, count_slots(params));
}

void count_add(mask rays, real each, int slot, __global scalar *params) {
    STORE_LANES(count_load(slot, params) + SELECT((real)0.0f, each, rays), slot, count_slots(params));
}

void count_set(mask rays, int slot, __global scalar *params) {
    STORE_LANES(SELECT((real)0.0f, (real)1.0f, rays), slot, count_slots(params));
}

// `each` evaluations for `purpose` by each ray of `rays`, about to be made
void count_evaluations(int purpose, mask rays, real each, __global scalar *params) {
    count_set(rays, SLOT_EVALUATING, params);
    count_add(rays, each, SLOT_COUNTS + purpose, params);
}

void count_iterations(mask rays, __global scalar *params) {
    count_add(rays & (count_load(SLOT_EVALUATING, params) > 0.0f), (real)1.0f, SLOT_ITERATIONS, params);
}

void count_march_purpose(int purpose, __global scalar *params) {
    count_slots(params)[SLOT_MARCH * LANES] = (scalar)purpose;
}

int march_purpose(__global scalar *params) {
    return (int)count_slots(params)[SLOT_MARCH * LANES];
}

void count_scope(mask rays, __global scalar *params) {
    count_set(rays, SLOT_SCOPE, params);
}

mask scoped(__global scalar *params) {
    return count_load(SLOT_SCOPE, params) > 0.0f;
}
