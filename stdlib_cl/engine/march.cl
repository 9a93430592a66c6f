// Sphere tracing of LANES rays at once; a lane stops on a hit (distance
// below the threshold, or <= 0 at the start: a camera inside a solid hits at
// t = 0), past MAX_DISTANCE, or after MAX_STEPS. `jitter` in [0, 1) shortens
// the first step by that fraction (dithering against banding, Syntopia part
// II: steps and glow then vary smoothly between neighbouring pixels). With
// cone marching, the camera's rays (a packet) go on from their cone's end.

// Where rays may start and must end (`t_enter`, `t_exit`), and which of
// the `active` ones are marched at all.
mask march_span(vec3 origin, vec3 dir, mask active, scalar pixel_angle, PARAMS_SPACE scalar *params,
                real *t_enter, real *t_exit) {
    *t_enter = 0.0f;
    *t_exit = (real)MAX_DISTANCE;
#if FEATURE_SCENE_BOUND
    // Rays start where they enter the scene's bounding sphere and miss once
    // they leave it: the empty space around the scene costs no evaluation.
    vec3 centre;
    real radius = scene_bound(params, &centre);
    // widened by the hit threshold at its far side: rays that pass within
    // the threshold of the scene hit it, bound or not
    radius = radius + hit_threshold(v3_length(v3_sub(origin, centre)) + radius, pixel_angle);
    mask in_bound = ray_sphere_span(origin, dir, centre, radius, t_enter, t_exit);
#if FEATURE_SCENE_HALF_SPACES
    // The scene's ground half-spaces lie outside the sphere: a ray that may
    // meet one is marched from its start to MAX_DISTANCE, as unbounded.
    mask clear = clear_of_half_spaces(origin, dir, hit_threshold(0.0f, pixel_angle), params);
    *t_enter = SELECT((real)0.0f, *t_enter, clear);
    *t_exit = SELECT((real)MAX_DISTANCE, *t_exit, clear);
    in_bound = in_bound | !clear;
#endif
    active = active & in_bound;
#endif
    return active;
}

// The march of the `active` rays from `t` to `t_exit`, after `first_step`
// steps of their cone (0 without; `steps`: each ray's count so far).
march_result march_from(vec3 origin, vec3 dir, mask active, real t, real t_exit, real steps, int first_step,
                        scalar pixel_angle, real jitter, PARAMS_SPACE scalar *params) {
    march_result r;
    r.t = t;
    r.hit = (mask)0;
    r.steps = steps;
    r.d = 0.0f;
#if FEATURE_GLOW
    r.closest = (real)MAX_DISTANCE;
#endif
#if FEATURE_OVERRELAX
    // Over-relaxed sphere tracing (Keinert et al. 2014): steps of
    // OVERRELAX * d while successive unbounding spheres overlap; when they
    // do not, the lane steps back and marches plainly from there on.
    real omega = (real)OVERRELAX;
    real previous_radius = 0.0f, step = 0.0f;
#endif
    for (int i = first_step; i < MAX_STEPS && ANY(active); i++) {
        COUNT_EVALUATIONS(march_purpose(params), active, 1.0f);
        real d = distance_estimate(v3_add(origin, v3_scale(dir, r.t)), params);
        r.steps = r.steps + SELECT((real)0.0f, (real)1.0f, active);
#if FEATURE_OVERRELAX
        // a long step that lands inside a solid (d < 0) overshot too
        mask overshot = active & (omega > 1.0f) & ((fabs(d) + previous_radius < step) | (d < 0.0f));
        if (ANY(overshot)) {
            // back to the previous point (its distance was previous_radius),
            // to step plainly from there
            r.t = SELECT(r.t, r.t - step, overshot);
            d = SELECT(d, previous_radius, overshot);
            omega = SELECT(omega, (real)1.0f, overshot);
        }
        previous_radius = fabs(d);
#endif
#if FEATURE_GLOW
        r.closest = SELECT(r.closest, min(r.closest, d), active);
#endif
        mask close = (d < hit_threshold(r.t, pixel_angle)) | (d <= 0.0f);
        r.hit = r.hit | (active & close);
#if FEATURE_FORWARD_NORMALS
        r.d = SELECT(r.d, d, active & close);
#endif
        active = active & !close;
#if FEATURE_DITHER
        if (i == first_step)
            d = d * (1.0f - jitter);
#endif
#if FEATURE_OVERRELAX
        step = d * omega;
        r.t = SELECT(r.t, r.t + step, active);
#else
        r.t = SELECT(r.t, r.t + d, active);
#endif
        active = active & (r.t < (real)MAX_DISTANCE);
#if FEATURE_SCENE_BOUND
        active = active & (r.t <= t_exit);
#endif
    }
    return r;
}

march_result march(vec3 origin, vec3 dir, mask active, scalar pixel_angle, real jitter,
                   PARAMS_SPACE scalar *params) {
    real t_enter, t_exit;
    active = march_span(origin, dir, active, pixel_angle, params, &t_enter, &t_exit);
    return march_from(origin, dir, active, t_enter, t_exit, (real)0.0f, 0, pixel_angle, jitter, params);
}

#if FEATURE_CONE
// The camera's rays of a work-item's pixels (a packet): those of packet
// `packet` of `cones`, whose cone was marched with its neighbours'
// (march_cones), go on from where it stopped.
march_result march_camera(vec3 origin, vec3 dir, mask active, scalar pixel_angle, real jitter,
                          PARAMS_SPACE scalar *params, const cone_packets *cones, int packet) {
    real t_enter, t_exit;
    active = march_span(origin, dir, active, pixel_angle, params, &t_enter, &t_exit);
    int first_step;
    real t = max(t_enter, cone_packet_start(origin, dir, t_enter, pixel_angle, &first_step, cones, packet));
    return march_from(origin, dir, active & (t <= t_exit), t, t_exit, SELECT((real)0.0f, (real)first_step, active),
                      first_step, pixel_angle, jitter, params);
}
#endif
