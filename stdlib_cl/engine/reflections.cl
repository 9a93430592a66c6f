#if FEATURE_REFLECTIONS
// Mirror reflections, up to REFLECTIONS bounces (no recursion): each surface
// keeps (1 - reflectivity) of its own colour and passes reflectivity on to
// what its mirror direction sees; a bounce that misses sees the background
// (with fog: the fog, and what it hits is fogged along the bounce).
vec3 reflected_color(vec3 origin, vec3 dir, march_result m, vec3 normal, vec3 seen_first,
                     scalar pixel_angle, PARAMS_SPACE scalar *params) {
    mask active = m.hit;
    vec3 p = v3_add(origin, v3_scale(dir, m.t));
    real threshold = hit_threshold(m.t, pixel_angle);
    real weight = 1.0f;
    vec3 seen_now = seen_first;
    vec3 color = v3((real)0.0f, 0.0f, 0.0f);
    for (int bounce = 0; bounce < REFLECTIONS; bounce++) {
        real reflectivity = SELECT((real)0.0f, surface_at(p, params).reflectivity, active);
        color = v3_add(color, v3_scale(seen_now, weight * (1.0f - reflectivity)));
        weight = weight * reflectivity;
        active = active & (reflectivity > 0.0f);
        if (!ANY(active))
            return color;
        dir = v3_sub(dir, v3_scale(normal, 2.0f * v3_dot(dir, normal)));
        vec3 start = v3_add(p, v3_scale(normal, 2.0f * threshold));
        COUNT_MARCH(COUNT_REFLECTIONS);
        march_result b = march(start, dir, active, pixel_angle, 0.0f, params);
        normal = hit_normal(start, dir, b, pixel_angle, params);
        p = v3_add(start, v3_scale(dir, b.t));
        threshold = hit_threshold(b.t, pixel_angle);
        vec3 seen = background_seen(dir);
        COUNT_SCOPE(b.hit);
        if (ANY(b.hit))
            seen = v3_select(seen, shade(p, normal, dir, threshold, b.steps, b.hit, params), b.hit);
#if FEATURE_FOG
        seen = fogged(seen, b.t, b.hit);     // the fog along the bounce
#endif
        seen_now = v3_select(seen_now, seen, active);
        active = active & b.hit;
    }
    return v3_add(color, v3_scale(seen_now, weight));
}
#endif
