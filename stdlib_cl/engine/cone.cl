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
// the surface, one evaluation instead of one per ray and step. `t_enter`,
// `t_exit`: where each ray's marching may start and must end; a cone's
// steps are its rays' first march steps (each ray's steps, max_steps
// included, count them). The cones of up to LANES packets (neighbouring
// blocks' camera rays, or a block's samples) are marched side by side, a
// packet a lane: one vector evaluation for all their axis points (one
// packet's cone at a time, in scalar arithmetic, took 15% of bulb-640's
// frame on Intel's runtime and 17% on PoCL; docs/performance.md).

// A packet's cone: its axis, its spreads, and the span of t it marches
// (from where the last of its active rays enters to where the last leaves).
typedef struct {
    uvec3 origin, dir;
    scalar spread_origin, spread_dir, t, t_last;
} cone_axis;

// A ray's distance from the axis, at its start and per unit of t.
real cone_own_origin(vec3 origin, cone_axis c) {
    return v3_length(v3_sub(origin, v3((real)c.origin.x, (real)c.origin.y, (real)c.origin.z)));
}

real cone_own_dir(vec3 dir, cone_axis c) {
    return v3_length(v3_sub(dir, v3((real)c.dir.x, (real)c.dir.y, (real)c.dir.z)));
}

// The cone of a packet whose mask has an active ray.
cone_axis cone_of(vec3 origin, vec3 dir, mask active, real t_enter, real t_exit) {
    cone_axis c;
    real weight = SELECT((real)0.0f, (real)1.0f, active);
    scalar share = 1.0f / lanes_sum(weight);
    c.origin = uniform_v3(share * lanes_sum(weight * origin.x), share * lanes_sum(weight * origin.y),
                          share * lanes_sum(weight * origin.z));
    c.dir = uniform_v3(share * lanes_sum(weight * dir.x), share * lanes_sum(weight * dir.y),
                       share * lanes_sum(weight * dir.z));
    c.spread_origin = lanes_max(weight * cone_own_origin(origin, c));
    c.spread_dir = lanes_max(weight * cone_own_dir(dir, c));
    c.t = -lanes_max(SELECT((real)-MAX_DISTANCE, -t_enter, active));
    c.t_last = lanes_max(SELECT((real)0.0f, t_exit, active));
    return c;
}

// Up to LANES packets' cones. `marched`: whether the packet has an active
// ray; the rest, where its cone stopped (`evaluated`: with the distance
// `distance` evaluated at t itself) after `steps` steps.
typedef struct {
    cone_axis axis[LANES];
    scalar t[LANES], distance[LANES];
    int steps[LANES], evaluated[LANES], marched[LANES];
} cone_packets;

// Packet `q` of `cones`: the cone of the rays `origin` + t `dir`, t in
// [t_enter, t_exit], of the mask `active`.
void cone_packet(vec3 origin, vec3 dir, mask active, real t_enter, real t_exit, cone_packets *cones, int q) {
    cones->marched[q] = ANY(active);
    if (cones->marched[q]) {
        cones->axis[q] = cone_of(origin, dir, active, t_enter, t_exit);
    } else {
        // no cone: its lane's axis is its first ray (march_cones evaluates
        // there, far from the scene)
        scalar start[6][LANES];
        STORE_LANES(origin.x, 0, start[0]);
        STORE_LANES(origin.y, 0, start[1]);
        STORE_LANES(origin.z, 0, start[2]);
        STORE_LANES(dir.x, 0, start[3]);
        STORE_LANES(dir.y, 0, start[4]);
        STORE_LANES(dir.z, 0, start[5]);
        cones->axis[q].origin = uniform_v3(start[0][0], start[1][0], start[2][0]);
        cones->axis[q].dir = uniform_v3(start[3][0], start[4][0], start[5][0]);
        cones->axis[q].spread_origin = cones->axis[q].spread_dir = 0.0f;
        cones->axis[q].t = 0.0f;
        cones->axis[q].t_last = -1.0f;
    }
}

// Marches the cones of the first `count` packets of `cones`.
NEVER_INLINE void march_cones(cone_packets *cones, int count, scalar pixel_angle, PARAMS_SPACE scalar *params) {
    // a packet a lane (the lanes past `count`: the last packet's axis, not marched)
    scalar axis[10][LANES];
    for (int q = 0; q < LANES; q++) {
        cone_axis c = cones->axis[min(q, count - 1)];
        axis[0][q] = c.origin.x, axis[1][q] = c.origin.y, axis[2][q] = c.origin.z;
        axis[3][q] = c.dir.x, axis[4][q] = c.dir.y, axis[5][q] = c.dir.z;
        axis[6][q] = c.spread_origin, axis[7][q] = c.spread_dir;
        axis[8][q] = q < count ? c.t : 0.0f, axis[9][q] = q < count ? c.t_last : -1.0f;
    }
    vec3 o = v3(LOAD_LANES(0, axis[0]), LOAD_LANES(0, axis[1]), LOAD_LANES(0, axis[2]));
    vec3 d = v3(LOAD_LANES(0, axis[3]), LOAD_LANES(0, axis[4]), LOAD_LANES(0, axis[5]));
    real spread_origin = LOAD_LANES(0, axis[6]), spread_dir = LOAD_LANES(0, axis[7]);
    real t = LOAD_LANES(0, axis[8]), t_last = LOAD_LANES(0, axis[9]);
    // over-relaxed as the rays are, with the same fallback
    real omega = 1.0f, previous_clear = 0.0f, step = 0.0f;
#if FEATURE_OVERRELAX
    omega = OVERRELAX;
#endif
    real distance = 0.0f, t_evaluated = -1.0f, steps = 0.0f;
    mask running = t < t_last;
    for (int i = 0; i < MAX_STEPS && ANY(running); i++) {
        COUNT_EVALUATIONS(COUNT_CAMERA, running, 1.0f);
        // a lane without a cone under way evaluates MAX_DISTANCE along its
        // axis, far from the scene, where the estimate costs least (as a
        // finished shadow ray does)
        real at = distance_estimate(v3_add(o, v3_scale(d, SELECT((real)MAX_DISTANCE, t, running))), params);
        distance = SELECT(distance, at, running);
        t_evaluated = SELECT(t_evaluated, t, running);
        steps = SELECT(steps, (real)(i + 1), running);
        real clear = distance - (spread_origin + t * spread_dir);
        mask back = running & (omega > 1.0f) & (clear + previous_clear < step);
        t = SELECT(t, t - step, back);
        clear = SELECT(clear, previous_clear, back);
        omega = SELECT(omega, (real)1.0f, back);
        // (not below the rays' hit threshold: a cone from one point, with no
        // spread, would otherwise creep towards the surface)
        running = running & !(clear <= max((CONE_STOP - 1.0f) * (spread_origin + t * spread_dir),
                                           HIT_THRESHOLD(t, pixel_angle)));
        previous_clear = SELECT(previous_clear, clear, running);
        step = SELECT(step, omega * clear, running);
        t = SELECT(t, t + step, running);
        running = running & (t < t_last);
    }
    scalar stopped[4][LANES];
    STORE_LANES(t, 0, stopped[0]);
    STORE_LANES(distance, 0, stopped[1]);
    STORE_LANES(steps, 0, stopped[2]);
    STORE_LANES(SELECT((real)0.0f, (real)1.0f, t_evaluated == t), 0, stopped[3]);
    for (int q = 0; q < count; q++) {
        cones->t[q] = stopped[0][q];
        cones->distance[q] = stopped[1][q];
        cones->steps[q] = (int)stopped[2][q];
        cones->evaluated[q] = stopped[3][q] != 0.0f;
    }
}

// Where packet `q`'s rays go on from after its cone, and its steps: from
// where the cone stopped, or where the last ball, evaluated there, still
// holds the point: it reaches further along the rays nearer the axis (each
// within its own spread of it), but not where it is within the hit
// threshold (a camera that close to a surface hits at t = 0, as one ray's
// march has it).
real cone_packet_start(vec3 origin, vec3 dir, real t_enter, scalar pixel_angle, int *steps,
                       const cone_packets *cones, int q) {
    *steps = 0;
    if (!cones->marched[q])
        return t_enter;
    *steps = cones->steps[q];
    cone_axis c = cones->axis[q];
    scalar t = cones->t[q];
    real further = (real)0.0f;
    if (cones->evaluated[q]) {
        real own_clear = (real)cones->distance[q] - (cone_own_origin(origin, c) + (real)t * cone_own_dir(dir, c));
        further = SELECT((real)0.0f, own_clear, own_clear > (real)HIT_THRESHOLD(t, pixel_angle));
    }
    return (real)t + further;
}
#endif
