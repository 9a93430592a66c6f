// The surface normal where a march hit (0 elsewhere).
vec3 hit_normal(vec3 origin, vec3 dir, march_result m, scalar pixel_angle, PARAMS_SPACE scalar *params) {
    vec3 normal = v3((real)0.0f, 0.0f, 0.0f);
    if (ANY(m.hit)) {
        vec3 p = v3_add(origin, v3_scale(dir, m.t));
        COUNT_SCOPE(m.hit);
        normal = v3_select(normal, estimate_hit_normal(p, m.d, hit_threshold(m.t, pixel_angle), params), m.hit);
    }
    return normal;
}
