#if FEATURE_PATH_TRACE
// The path tracer's colour of one sample (stdlib_cl/pathtrace.cl, after this file).
vec3 path_color(vec3 origin, vec3 dir, march_result m, vec3 normal, scalar pixel_angle, lane_uint key,
                PARAMS_SPACE scalar *params);
#endif

// Colour seen along one ray: the shaded surface or the background, then
// transparency, reflections, fog and glow.
vec3 trace_color(vec3 origin, vec3 dir, march_result m, vec3 normal, scalar pixel_angle,
                 PARAMS_SPACE scalar *params) {
    vec3 color = background_seen(dir);
    if (ANY(m.hit)) {
        vec3 p = v3_add(origin, v3_scale(dir, m.t));
        real threshold = hit_threshold(m.t, pixel_angle);
        COUNT_SCOPE(m.hit);
        color = v3_select(color, shade(p, normal, dir, threshold, m.steps, m.hit, params), m.hit);
    }
#if FEATURE_TRANSPARENCY
    color = transmitted_color(origin, dir, m, normal, color, pixel_angle, params);
#endif
#if FEATURE_REFLECTIONS
    color = reflected_color(origin, dir, m, normal, color, pixel_angle, params);
#endif
#if FEATURE_FOG
    color = fogged(color, m.t, m.hit);
#endif
#if FEATURE_TRANSPARENT_BACKGROUND
    // a miss is empty (zero colour and, in the kernel, zero coverage), fog
    // or no fog: RGB is premultiplied by the coverage
    color = v3_select(v3((real)0.0f, 0.0f, 0.0f), color, m.hit);
#endif
#if FEATURE_GLOW
    color = v3_add(color, glow_color(m));
#endif
    return color;
}
