#if FEATURE_TRANSPARENCY
// Snell refraction of `dir` at a surface with `normal` facing it, for the
// ratio eta = n_from / n_to; under total internal reflection the ray goes on
// unbent (one transmission per ray, no internal bounces).
vec3 refracted(vec3 dir, vec3 normal, real eta) {
    real cos_in = -v3_dot(dir, normal);
    real k = 1.0f - eta * eta * (1.0f - cos_in * cos_in);
    vec3 bent = v3_add(v3_scale(dir, eta), v3_scale(normal, eta * cos_in - sqrt(max(k, 0.0f))));
    return v3_select(v3_normalize(bent), dir, k < 0.0f);
}

// Through a transparent solid entered at p (transparency as the dissertation
// plan asks, refraction as in Hong and Kook's ray tracer): the ray `dir`
// refracts in (ratio 1 / ior), marches inside to the far side and refracts
// out; returns the way out, and in *out_start where the ray goes on (lifted
// off the far side). Lanes not `active` are not marched.
vec3 through_solid(vec3 p, vec3 dir, vec3 normal, real ior, real threshold, mask active, vec3 *out_start,
                   PARAMS_SPACE scalar *params) {
    vec3 inside_dir = refracted(dir, normal, 1.0f / ior);
    // Inside is where the distance is below the hit threshold, as at the hit
    // `p` itself. A signed distance is marched by the depth -d; the inside of
    // an escape-time fractal has no depth (its estimate is about 0 there),
    // so steps are at least `shortest`: the scene's bounding diameter fits
    // in MAX_STEPS of them. Gaps narrower than a step are passed over.
    real shortest = threshold;
#if FEATURE_SCENE_BOUND
    vec3 centre;
    shortest = max(shortest, 2.0f * scene_bound(params, &centre) / (real)MAX_STEPS);
#endif
    real t = 0.0f, t_inside = 0.0f;
    mask marching = active;
    for (int i = 0; i < MAX_STEPS && ANY(marching); i++) {
        COUNT_EVALUATIONS(COUNT_REFRACTION, marching, 1.0f);
        real d = distance_estimate(v3_add(p, v3_scale(inside_dir, t)), params);
        marching = marching & (d < threshold);
        t_inside = SELECT(t_inside, t, marching);
        t = SELECT(t, t + max(-d, shortest), marching);
        marching = marching & (t < (real)MAX_DISTANCE);
    }
    // the far side lies between the last point inside and the first one out
    for (int i = 0; i < 8; i++) {
        real middle = 0.5f * (t_inside + t);
        COUNT_EVALUATIONS(COUNT_REFRACTION, active, 1.0f);
        mask within = distance_estimate(v3_add(p, v3_scale(inside_dir, middle)), params) < threshold;
        t_inside = SELECT(t_inside, middle, within);
        t = SELECT(middle, t, within);
    }
    vec3 exit = v3_add(p, v3_scale(inside_dir, t));
    COUNT_SCOPE(active);
    COUNT_MARCH(COUNT_REFRACTION);
    vec3 exit_normal = estimate_normal(exit, threshold, params);
    *out_start = v3_add(exit, v3_scale(exit_normal, 2.0f * threshold));
    return refracted(inside_dir, v3_scale(exit_normal, -1.0f), ior);
}

// Transparency: what the ray sees through the solid (through_solid) is
// mixed in by `transparency`.
vec3 transmitted_color(vec3 origin, vec3 dir, march_result m, vec3 normal, vec3 seen,
                       scalar pixel_angle, PARAMS_SPACE scalar *params) {
    vec3 p = v3_add(origin, v3_scale(dir, m.t));
    surface s = surface_at(p, params);
    mask active = m.hit & (s.transparency > 0.0f);
    if (!ANY(active))
        return seen;
    vec3 out_start;
    vec3 out_dir = through_solid(p, dir, normal, s.ior, hit_threshold(m.t, pixel_angle), active, &out_start, params);
    march_result beyond = march(out_start, out_dir, active, pixel_angle, 0.0f, params);
    vec3 beyond_normal = hit_normal(out_start, out_dir, beyond, pixel_angle, params);
    vec3 far = background_seen(out_dir);
    if (ANY(beyond.hit)) {
        COUNT_SCOPE(beyond.hit);
        vec3 q = v3_add(out_start, v3_scale(out_dir, beyond.t));
        far = v3_select(far, shade(q, beyond_normal, out_dir, hit_threshold(beyond.t, pixel_angle),
                                   beyond.steps, beyond.hit, params), beyond.hit);
    }
#if FEATURE_FOG
    far = fogged(far, beyond.t, beyond.hit);   // the fog beyond the solid
#endif
    real mixing = SELECT((real)0.0f, s.transparency, active);
    return v3_add(v3_scale(seen, 1.0f - mixing), v3_scale(far, mixing));
}
#endif
