// Ambient occlusion by sampling the distance along the normal (Syntopia,
// "Distance Estimated 3D Fractals" part II; Quilez): where the surface is
// open, d(p + n i delta) = i delta; nearby geometry makes it smaller.
// Returns 1 (open) .. 0 (fully occluded), scaled by `strength`.
// The farthest sample comes first: once a sample k is open (d_k >= k delta),
// every nearer one is too, since the distance changes by at most the step
// between them (d_i >= d_k - (k - i) delta >= i delta), so the ray's
// remaining samples would add nothing and are not taken.

// A sample `along` the normal, whose distance is `d`: its share of the
// occlusion, where the ray is not yet open.
void occlusion_sample(real along, real d, real delta, real *occlusion, real *weight, mask *open) {
    *occlusion += SELECT(*weight * max(along - d, 0.0f) / delta, (real)0.0f, *open);
    *open = *open | (d >= along);
    *weight *= 2.0f;
}

real ambient_occlusion(vec3 p, vec3 normal, real delta, real strength, PARAMS_SPACE scalar *params) {
    real occlusion = 0.0f;
    real weight = 1.0f / 32.0f;      // 0.5^i for the sample i
    mask open = (mask)0;
    // the farthest sample alone (where it is open, no other is taken), then
    // the others two at a time, side by side (`distance_estimates`)
    for (int i = 5; i >= 1 && !ALL(open); i -= i == 5 ? 1 : 2) {
        real along = delta * (real)i, nearer = delta * (real)(i - 1);
        real d, d_nearer;
        if (i < 5) {
            COUNT_EVALUATIONS(COUNT_AO, scoped(params) & !open, 2.0f);
            distance_estimates(v3_add(p, v3_scale(normal, along)), v3_add(p, v3_scale(normal, nearer)),
                               &d, &d_nearer, params);
        } else {
            COUNT_EVALUATIONS(COUNT_AO, scoped(params) & !open, 1.0f);
            d = distance_estimate(v3_add(p, v3_scale(normal, along)), params);
        }
        occlusion_sample(along, d, delta, &occlusion, &weight, &open);
        if (i < 5)
            occlusion_sample(nearer, d_nearer, delta, &occlusion, &weight, &open);
    }
    return clamp(1.0f - strength * occlusion, 0.0f, 1.0f);
}

// The cheap ambient occlusion of Syntopia part II: rays that needed many
// steps passed close to much geometry. 1 at no steps, falling with the count.
real step_occlusion(real steps, real strength) {
    return clamp(1.0f - strength * steps / (steps + 32.0f), 0.0f, 1.0f);
}
