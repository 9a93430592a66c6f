// Ambient occlusion by sampling the distance along the normal (Syntopia,
// "Distance Estimated 3D Fractals" part II; Quilez): where the surface is
// open, d(p + n i delta) = i delta; nearby geometry makes it smaller.
// Returns 1 (open) .. 0 (fully occluded), scaled by `strength`.
real ambient_occlusion(vec3 p, vec3 normal, real delta, real strength, __constant scalar *params) {
    real occlusion = 0.0f;
    real weight = 0.5f;
    for (int i = 1; i <= 5; i++) {
        real along = delta * (real)i;
#if FEATURE_COUNT
        count_evaluations(COUNT_AO, scoped(params), 1.0f, params);
#endif
        real d = distance_estimate(v3_add(p, v3_scale(normal, along)), params);
        occlusion += weight * max(along - d, 0.0f) / delta;
        weight *= 0.5f;
    }
    return clamp(1.0f - strength * occlusion, 0.0f, 1.0f);
}

// The cheap ambient occlusion of Syntopia part II: rays that needed many
// steps passed close to much geometry. 1 at no steps, falling with the count.
real step_occlusion(real steps, real strength) {
    return clamp(1.0f - strength * steps / (steps + 32.0f), 0.0f, 1.0f);
}
