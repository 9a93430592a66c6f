// Tom Lowe's Mandelbox, z -> scale * spherefold(boxfold(z)) + p, with the
// scalar running derivative dr -> |scale| fold dr + 1 and DE = |z| / |dr|:
// Syntopia, "Distance Estimated 3D Fractals", part VI (after Buddhi's
// estimator); the formulas of LANGUAGE.md, "Fractals".
//
// There is no bailout, so z and dr grow like |scale|^n outside the set, and
// dr also grows inside it. To stay finite both are kept multiplied by a
// per-lane factor k (z_true = z / k, dr_true = dr / k), and k shrinks
// whenever z or dr passes 1e6. Written in the scaled values, the folds
// compare with fold_limit k and radius^2 k^2, and the translation adds p k
// and the derivative k; DE = |z| / dr does not depend on k.

// The iteration, recording its orbit in `trap`.
real mandelbox_orbit(vec3 p, real scale, real min_radius, real fixed_radius, real fold_limit, int iterations, orbit_trap *trap) {
    vec3 z = p;
    real dr = 1.0f, k = 1.0f;
    real min2 = min_radius * min_radius, fixed2 = fixed_radius * fixed_radius;
    for (int i = 0; i < iterations; i++) {
        // Box fold: reflect each coordinate beyond +-fold_limit back inside.
        real limit = fold_limit * k;
        z = v3(clamp(z.x, -limit, limit) * 2.0f - z.x, clamp(z.y, -limit, limit) * 2.0f - z.y,
               clamp(z.z, -limit, limit) * 2.0f - z.z);
        // Sphere fold: invert in the sphere of radius fixed_radius inside
        // it (factor fixed^2 / r^2), linearly inside min_radius (factor
        // fixed^2 / min^2): the factor is fixed^2 / r^2 clamped to
        // [1, fixed^2 / min^2]. (The floor on r^2 keeps 0 / 0 out once k^2
        // has underflowed; it changes nothing while min_radius k > 1e-19.)
        real r2 = max(v3_dot(z, z), (real)FLT_MIN);
        real fold = clamp(fixed2 * (k * k) / r2, 1.0f, fixed2 / min2);
        // Scale and translate.
        z = v3_add(v3_scale(z, fold * scale), v3_scale(p, k));
        dr = dr * fold * fabs(scale) + k;
        orbit_trap_add(trap, v3_scale(z, 1.0f / max(k, (real)1e-30f)), MASK_TRUE);
        // Renormalise lanes whose z or dr got large.
        real largest = max(max(fabs(z.x), fabs(z.y)), max(fabs(z.z), dr));
        mask large = largest > 1e6f;
        if (ANY(large)) {
            real shrink = SELECT((real)1.0f, 1.0f / largest, large);
            z = v3_scale(z, shrink);
            dr = dr * shrink;
            k = k * shrink;
        }
    }
    // dr > 0; the floor only matters once k has underflowed to 0 inside the
    // set, where z and dr may both underflow and the DE is ~0 either way.
    return v3_length(z) / max(dr, 1e-30f);
}

//: fractal mandelbox(scale: num = 2, min_radius: num = 0.5 >0 <=fixed_radius, fixed_radius: num = 1 >0, fold_limit: num = 1 >0, iterations: int = 12 1..1000)
real de_mandelbox(vec3 p, real scale, real min_radius, real fixed_radius, real fold_limit, int iterations) {
    return mandelbox_orbit(p, scale, min_radius, fixed_radius, fold_limit, iterations, 0);
}

// The orbit trap of the same iteration, for `.color(orbit_trap(...))`.
real mandelbox_orbit_trap(vec3 p, real scale, real min_radius, real fixed_radius, real fold_limit, int iterations, int kind) {
    orbit_trap trap = orbit_trap_start();
    mandelbox_orbit(p, scale, min_radius, fixed_radius, fold_limit, iterations, &trap);
    return orbit_trap_value(trap, kind);
}

// A sphere holding the set (the points whose orbits do not escape), with
// z != 0 outside, so the DE is > 0 there. Let L = fold_limit, s = scale and
// P = |p_i| the largest coordinate of p, p_i > 0 say, and x_n the i-th
// coordinate of z_n. The box fold maps x > 2L to 2L - x, x < -2L to
// -2L - x, and the sphere fold multiplies by a factor >= 1.
// - s > 1 and P > B = 2L (s + 1) / (s - 1): from x >= P, the next
//   coordinate is <= P - s (x - 2L) <= -2L, and the one after it is
//   >= P + s (s (x - 2L) - P - 2L) >= x: the orbit alternates in sign and
//   grows, and never reaches 0. Outside the cube [-B, B]^3, so outside the
//   sphere of radius sqrt(3) B.
// - s <= 0 and P > 2L: from x >= P > 2L the next coordinate is
//   P + |s| fold (x - 2L) >= P: radius sqrt(3) 2L.
// - 0 < s <= 1: no bound is proven (+inf).
real mandelbox_bound_radius(real scale, real min_radius, real fixed_radius, real fold_limit, int iterations) {
    real cube = SELECT(2.0f * fold_limit * (scale + 1.0f) / (scale - 1.0f), 2.0f * fold_limit, scale <= 0.0f);
    return SELECT((real)INFINITY, sqrt(3.0f) * cube, (scale <= 0.0f) | (scale > 1.0f));
}
