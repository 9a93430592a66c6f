#if FEATURE_CONE
// Cone marching hands a packet over to its rays where the distance at its
// axis falls below CONE_STOP times its spread.
#define CONE_STOP 2.0f

// Reductions over the lanes of a work-item (its packet of rays).
scalar lanes_sum(real v) {
    scalar lanes[LANES];
    STORE_LANES(v, 0, lanes);
    scalar sum = lanes[0];
    for (int i = 1; i < LANES; i++)
        sum += lanes[i];
    return sum;
}

scalar lanes_max(real v) {
    scalar lanes[LANES];
    STORE_LANES(v, 0, lanes);
    scalar most = lanes[0];
    for (int i = 1; i < LANES; i++)
        most = max(most, lanes[i]);
    return most;
}

// Cone marching of a packet (cone tracing, Amanatides 1984, marched as the
// demoscene does): one distance at the packet's axis point c(t) = o + t d
// (o, d: the mean origin and direction of its rays) bounds the distance at
// each ray's point at t, which lies within spread(t) = max |o_i - o| +
// t max |d_i - d| of c(t); while d(c) > spread, every ray may go on by
// d(c) - spread. Where d(c) < CONE_STOP spread (the cone could step only
// a little) the rays are marched one by one from the t reached: far from
// the surface, one evaluation instead of one per ray and step. The axis
// point is one point for all lanes, so it is evaluated with scalar
// arithmetic (`uniform_distance_estimate`, the scene's estimate in scalar
// types): a fraction of a vector step's cost. `t_enter`, `t_exit`: where
// each ray's marching may start and must end; `steps`: the cone's steps,
// which are its rays' first march steps (each ray's steps, max_steps
// included, count them).
real cone_start(vec3 origin, vec3 dir, mask active, real t_enter, real t_exit, scalar pixel_angle,
                int *steps, PARAMS_SPACE scalar *params) {
    *steps = 0;
    if (!ANY(active))
        return t_enter;
    real weight = SELECT((real)0.0f, (real)1.0f, active);
    scalar share = 1.0f / lanes_sum(weight);
    uvec3 o = uniform_v3(share * lanes_sum(weight * origin.x), share * lanes_sum(weight * origin.y),
                         share * lanes_sum(weight * origin.z));
    uvec3 d = uniform_v3(share * lanes_sum(weight * dir.x), share * lanes_sum(weight * dir.y),
                         share * lanes_sum(weight * dir.z));
    vec3 axis_origin = v3((real)o.x, (real)o.y, (real)o.z), axis_dir = v3((real)d.x, (real)d.y, (real)d.z);
    real own_origin = v3_length(v3_sub(origin, axis_origin)), own_dir = v3_length(v3_sub(dir, axis_dir));
    scalar spread_origin = lanes_max(weight * own_origin), spread_dir = lanes_max(weight * own_dir);
    scalar t = -lanes_max(SELECT((real)-MAX_DISTANCE, -t_enter, active));
    scalar t_last = lanes_max(SELECT((real)0.0f, t_exit, active));
    // over-relaxed as the rays are, with the same fallback
    scalar omega = 1.0f, previous_clear = 0.0f, step = 0.0f;
#if FEATURE_OVERRELAX
    omega = OVERRELAX;
#endif
    scalar distance = 0.0f, t_evaluated = -1.0f;
    for (int i = 0; i < MAX_STEPS && t < t_last; i++) {
        COUNT_EVALUATIONS(COUNT_CAMERA, (LANE_X == 0.0f) & (LANE_Y == 0.0f), 1.0f);
        distance = uniform_distance_estimate(uniform_v3_add(o, uniform_v3_scale(d, t)), params);
        t_evaluated = t;
        *steps = i + 1;
        // the radius of the empty ball about every ray's point at t
        scalar clear = distance - (spread_origin + t * spread_dir);
        if (omega > 1.0f && clear + previous_clear < step) {
            t -= step;
            clear = previous_clear;
            omega = 1.0f;
        }
        // (not below the rays' hit threshold: a cone from one point, with no
        // spread, would otherwise creep towards the surface)
        if (clear <= max((CONE_STOP - 1.0f) * (spread_origin + t * spread_dir), HIT_THRESHOLD(t, pixel_angle)))
            break;
        previous_clear = clear;
        step = omega * clear;
        t += step;
    }
    // where the last ball still holds the point of t: it reaches further
    // along the rays nearer the axis (each within its own spread of it),
    // but not where it is within the hit threshold (a camera that close to
    // a surface hits at t = 0, as one ray's march has it)
    real further = (real)0.0f;
    if (t_evaluated == t) {
        real own_clear = (real)distance - (own_origin + (real)t * own_dir);
        further = SELECT((real)0.0f, own_clear, own_clear > (real)HIT_THRESHOLD(t, pixel_angle));
    }
    return (real)t + further;
}
#endif
