// The level-N Menger sponge filling the cube [-1,1]^3 (LANGUAGE.md,
// "Fractals"): the cube with, at each level, the central cross of three
// square bars of every cell removed. Syntopia, "Distance Estimated 3D
// Fractals", part III (folding space) and Quilez, "Menger fractal".
//
// The sponge is the cube minus, per level, the bars of that level, bars
// that run through the whole cube. Its estimate is the largest of the exact
// signed distances to the cube and to the outside of each level's bars:
// each of those sets contains the sponge, so each distance, and so their
// maximum, is at most the distance to the sponge (it is the exact distance
// inside). A cell's bars are found by folding: abs() moves the point to one
// octant of its cell, the bars' cross section in it is the square
// [0, 1/3]^2 of the two smallest coordinates, and a = 3a or 3a - 2 enters
// the next level's cell (cell coordinates run over [-1, 1], cells at level
// n are 3^-n the size of the cube, the scale divided out).

// A coordinate in [0, 1] of a cell as the coordinate in [-1, 1] of the
// third it falls in (beyond the cell, that of the outer third).
real menger_third(real a) {
    return SELECT(3.0f * a, 3.0f * a - 2.0f, a > 1.0f / 3.0f);
}

// The iteration, recording its orbit in `trap`.
real menger_orbit(vec3 p, int level, orbit_trap *trap) {
    // Clamping p to a box holding the sponge only brings it closer to the
    // sponge (so the estimate stays a lower bound) and keeps |p|^2 finite.
    p = v3(clamp(p.x, -1e15f, 1e15f), clamp(p.y, -1e15f, 1e15f), clamp(p.z, -1e15f, 1e15f));
    // The cube [-1, 1]^3 (as sd_box).
    vec3 q = v3_sub(v3_abs(p), v3(1.0f, 1.0f, 1.0f));
    real d = v3_length(v3(max(q.x, 0.0f), max(q.y, 0.0f), max(q.z, 0.0f))) + min(max(q.x, max(q.y, q.z)), 0.0f);
    vec3 a = p;
    real size = 1.0f;
    for (int i = 0; i < level; i++) {
        a = v3_abs(a);
        real lowest = min(a.x, min(a.y, a.z));
        real middle = max(min(a.x, a.y), min(max(a.x, a.y), a.z));
        // Signed distance to the nearest bar, the one along the largest axis.
        real u = middle - 1.0f / 3.0f, v = lowest - 1.0f / 3.0f;
        real ou = max(u, 0.0f), ov = max(v, 0.0f);
        real bar = sqrt(ou * ou + ov * ov) + min(max(u, v), 0.0f);
        d = max(d, -bar * size);
        a = v3(menger_third(a.x), menger_third(a.y), menger_third(a.z));
        orbit_trap_add(trap, a, MASK_TRUE);
        size = size * (1.0f / 3.0f);
    }
    return d;
}

//: fractal menger(level: int = 4 0..10)
real de_menger(vec3 p, int level) {
    return menger_orbit(p, level, 0);
}

// The orbit trap of the same iteration, for `.color(orbit_trap(...))`.
real menger_orbit_trap(vec3 p, int level, int kind) {
    orbit_trap trap = orbit_trap_start();
    menger_orbit(p, level, &trap);
    return orbit_trap_value(trap, kind);
}

// All of the sponge lies in the cube, within sqrt(3) of the origin.
real menger_bound_radius(int level) {
    return (real)sqrt(3.0f);
}
