// Shadow rays toward a light, marched at most MAX_STEPS steps and no further
// than `max_t` (the light's distance, or MAX_DISTANCE for a directional
// light). Rays of lanes that are not `active` are not marched.

// Where a shadow ray samples the estimate: at t, or for a lane whose ray is
// done, where an estimate that iterates (a fractal's, a formula's) costs
// least: at the ray's end, max_t, outside the scene's bound. A blocked ray
// stops at a surface, where the orbit iterates longest and would keep the
// other lanes' loop going (bulb-640 2-3% on Intel's runtime and PoCL);
// with no iterations the choice only costs (csg.frac 1.5%).
real shadow_sample_t(real t, real max_t, mask active) {
#if FEATURE_ITERATED_ESTIMATE
    return SELECT(max_t, t, active);
#else
    return t;
#endif
}

// Hard shadow: 0 where the ray hits a surface before the light, else 1.
// Over-relaxed (Keinert et al. 2014, as `march` is): steps of 1.6 d while
// successive unbounding spheres overlap; where they do not, the ray steps
// back and goes on plainly. A shadow ray leaves a surface, where d grows
// along it and plain steps creep: half of bulb-640's shadow evaluations
// were within 20 thresholds of the start (1.3 and 2 saved less: 2
// overshoots often, and falls back).
real hard_shadow(vec3 origin, vec3 to_light, real max_t, real threshold, mask active,
                 PARAMS_SPACE scalar *params) {
    real t = 2.0f * threshold;
    real visible = 1.0f;
    real omega = 1.6f, previous = 0.0f, step = 0.0f;
    for (int i = 0; i < MAX_STEPS && ANY(active); i++) {
        COUNT_EVALUATIONS(COUNT_SHADOWS, active, 1.0f);
        real d = distance_estimate(v3_add(origin, v3_scale(to_light, shadow_sample_t(t, max_t, active))), params);
        mask overshot = active & (omega > 1.0f) & (d + previous < step);
        t = SELECT(t, t - step, overshot);
        d = SELECT(d, previous, overshot);
        omega = SELECT(omega, (real)1.0f, overshot);
        mask blocked = active & (d < threshold);
        visible = SELECT(visible, (real)0.0f, blocked);
        previous = d;
        step = omega * max(d, threshold);
        t = t + step;
        active = active & !blocked & (t < max_t);
    }
    return visible;
}

// Hard shadow in a scene with transparent solids: a solid passes its
// `transparency` of the light (straight through: no refraction, no
// caustics), so the ray steps into it, marches through it by the depth
// (-d, as `transmitted_color` does) and on from its far side; an opaque
// solid blocks it. A solid counts once, on the step where the distance
// first falls below the threshold; the next one counts only after the ray
// is clear of the surface by the threshold again. (Leaving by a fixed step
// instead re-entered the same solid under oblique light: a slab counted
// two to four times.) Scenes without transparency keep `hard_shadow`: on
// PoCL a longer body in this loop costs more than the steps it saves.
real hard_shadow_through(vec3 origin, vec3 to_light, real max_t, real threshold, mask active,
                         PARAMS_SPACE scalar *params) {
    real t = 2.0f * threshold;
    real visible = 1.0f;
    mask clear_of_surface = MASK_TRUE;
    for (int i = 0; i < MAX_STEPS && ANY(active); i++) {
        vec3 q = v3_add(origin, v3_scale(to_light, shadow_sample_t(t, max_t, active)));
        COUNT_EVALUATIONS(COUNT_SHADOWS, active, 1.0f);
        real d = distance_estimate(q, params);
        mask entering = active & clear_of_surface & (d < threshold);
        if (ANY(entering)) {
            real clear = SELECT((real)0.0f, surface_at(q, params).transparency, entering);
            visible = SELECT(visible, visible * clear, entering);
            active = active & !(entering & (clear <= 0.0f));
        }
        clear_of_surface = d >= threshold;
        // outside: sphere tracing; inside: steps of the depth; at least the
        // threshold across a surface
        t = t + max(fabs(d), threshold);
        active = active & (t < max_t);
    }
    return visible;
}

// The smallest d / t along the shadow ray on [a, c], where the sample at b
// inside it, `ratio` = d(b) / b, is below both ends: halvings of the
// bracket about its lowest point, two evaluations each.
real lowest_ratio(vec3 origin, vec3 to_light, real a, real b, real c, real ratio,
                  PARAMS_SPACE scalar *params) {
    for (int i = 0; i < 4; i++) {
        real left = 0.5f * (a + b), right = 0.5f * (b + c);
        COUNT_EVALUATIONS(COUNT_SHADOWS, scoped(params), 2.0f);
        real at_left = distance_estimate(v3_add(origin, v3_scale(to_light, left)), params) / left;
        real at_right = distance_estimate(v3_add(origin, v3_scale(to_light, right)), params) / right;
        mask to_left = at_left < ratio;
        mask to_right = !to_left & (at_right < ratio);
        // [a, b] about left, [b, c] about right, or [left, right] about b
        a = SELECT(SELECT(left, b, to_right), a, to_left);
        c = SELECT(SELECT(right, c, to_right), b, to_left);
        b = SELECT(SELECT(b, right, to_right), left, to_left);
        ratio = SELECT(SELECT(ratio, at_right, to_right), at_left, to_left);
    }
    return ratio;
}

// Soft shadow, after Quilez ("penumbra"): the smallest k * d / t along the
// ray, so rays that graze an occluder are partly lit; larger k, harder edge.
// The smallest d / t lies between samples, and where sphere tracing samples
// jumps from pixel to pixel: read off the samples, the penumbra is grainy
// wherever the distance has a kink there (the edges of CSG, concave
// surfaces). So a local minimum of the samples' d / t, where the light may
// be dimmed (k d / t < 2: by the distance's slope of at most 1, less than
// half the sample's d / t cannot lie between its neighbours), is refined
// (`lowest_ratio`). Over-relaxed as the hard-shadow march is: an overshooting
// sample (its sphere and the last one's do not overlap) still dims the light
// by its d / t, but the samples of the dip test are the ones stepped from.
real soft_shadow(vec3 origin, vec3 to_light, real max_t, real threshold, real k, mask active,
                 PARAMS_SPACE scalar *params) {
    real t = 2.0f * threshold;
    real visible = 1.0f;
    // the previous two samples: ray distances and d / t; the last one's d
    real t_before = t, t_last = t;
    real ratio_before = (real)1e30f, ratio_last = (real)1e30f, d_last = 0.0f;
    real omega = 1.6f, step = 0.0f;
    for (int i = 0; i < MAX_STEPS && ANY(active); i++) {
        COUNT_EVALUATIONS(COUNT_SHADOWS, active, 1.0f);
        real d = distance_estimate(v3_add(origin, v3_scale(to_light, shadow_sample_t(t, max_t, active))), params);
        real ratio = d / t;
        visible = SELECT(visible, min(visible, k * ratio), active);
        mask overshot = active & (omega > 1.0f) & (d + d_last < step);
        mask sampled = active & !overshot;
        mask dip = sampled & (ratio_last <= ratio_before) & (ratio_last <= ratio) & (k * ratio_last < 2.0f);
        if (ANY(dip)) {
            COUNT_SCOPE(dip);
            real lowest = lowest_ratio(origin, to_light, t_before, t_last, t, ratio_last, params);
            visible = SELECT(visible, min(visible, k * lowest), dip);
        }
        mask blocked = active & (d < threshold);
        visible = SELECT(visible, (real)0.0f, blocked);
        t_before = SELECT(t_before, t_last, sampled);
        ratio_before = SELECT(ratio_before, ratio_last, sampled);
        t_last = SELECT(t_last, t, sampled);
        ratio_last = SELECT(ratio_last, ratio, sampled);
        d_last = SELECT(d_last, d, sampled);
        omega = SELECT(omega, (real)1.0f, overshot);
        step = omega * max(d_last, threshold);
        t = t_last + step;
        active = active & !blocked & (t < max_t);
    }
    return clamp(visible, 0.0f, 1.0f);
}
