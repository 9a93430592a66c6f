// The kernel of a program that computes the scene's distance estimates
// alone (fractalc/emit.py emit_distance; Scene.distance and everything that
// samples the estimate: meshes, check --de), and of every render program.
// Spliced after the scene's `distance_estimate`.

// Distance estimates at points: `points` holds count x's, then count y's,
// then count z's (count a multiple of LANES); `distances` gets count values.
__kernel VECTOR_LANES_HINT void distance_at_points(__global const scalar *points, __global scalar *distances,
                       PARAMS_SPACE scalar *params, int count) {
    int i = get_global_id(0);
    vec3 p = v3(LOAD_LANES(i, points), LOAD_LANES(i, points + count),
                LOAD_LANES(i, points + 2 * count));
    STORE_LANES(distance_estimate(p, params), i, distances);
}
