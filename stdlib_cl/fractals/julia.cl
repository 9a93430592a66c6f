// Quaternion Julia sets q -> q^2 + c, sliced at a fixed k component, with
// the distance estimate DE = 0.5 ln(r) r / dr and the running derivative
// dr -> 2 |q| dr (Hart, Sandin and Kauffman 1989; Syntopia, "Distance
// Estimated 3D Fractals", part IV); the formulas of LANGUAGE.md, "Fractals".
//
// Overflow, so that the estimate stays finite for every valid argument:
// - |q|^2 is at most 1e12 on a step that keeps iterating. A step from a
//   larger |q| escapes: the new q and dr are stored divided by |q|^2, whose
//   logarithm goes to `log_scale`; the final
//   DE = 0.5 (log_scale + ln|q|) |q| / dr is then the same number.
//   (An orbit passing |q| ~ 1e6 is treated as escaped even if the bailout
//   is larger than that.)
// - dr is capped at 1e30 (only orbits that stay bounded get there, whose
//   DE is then below 1e-23 either way).

// The iteration, recording its orbit in `trap`.
real julia_orbit(vec3 p, real cx, real cy, real cz, real cw, real slice, int iterations, real bailout, orbit_trap *trap) {
    // q = x + y i + z j + w k; c likewise (real part first).
    real x = p.x, y = p.y, z = p.z, w = slice;
    real dr = 1.0f;
    real log_scale = 0.0f;
    mask active = MASK_TRUE;
    for (int i = 0; i < iterations; i++) {
        real r2 = x * x + y * y + z * z + w * w;
        real r = sqrt(r2);
        active = active & (r <= bailout);
        if (!ANY(active)) break;
        // q^2 = (x^2 - |v|^2, 2 x v) for q = (x, v).
        real sx = x * x - (y * y + z * z + w * w), sy = 2.0f * x * y, sz = 2.0f * x * z, sw = 2.0f * x * w;
        real scale = 1.0f;
        mask escapes = active & (r2 > 1e12f);
        if (ANY(escapes)) {
            scale = SELECT(scale, 1.0f / r2, escapes);
            log_scale = SELECT(log_scale, log(r2), escapes);
        }
        x = SELECT(x, (sx + cx) * scale, active);
        y = SELECT(y, (sy + cy) * scale, active);
        z = SELECT(z, (sz + cz) * scale, active);
        w = SELECT(w, (sw + cw) * scale, active);
        dr = SELECT(dr, min(2.0f * r * dr, 1e30f) * scale, active);
        orbit_trap_add(trap, v3(x, y, z), active & !escapes);
        active = active & !escapes;
    }
    real r = sqrt(x * x + y * y + z * z + w * w);
    real de = 0.5f * (log(r) + log_scale) * r / dr;
    // DE = 0 at r = 0 or dr = 0; min() keeps it finite where |p| overflows (> 1e19 in float).
    return SELECT(min(de, 1e30f), (real)0.0f, (r == 0.0f) | (dr == 0.0f));
}

//: fractal julia(c: vec4 = (-0.2, 0.6, 0.2, 0), slice: num = 0, iterations: int = 12 1..1000, bailout: num = 4 >0)
real de_julia(vec3 p, real cx, real cy, real cz, real cw, real slice, int iterations, real bailout) {
    return julia_orbit(p, cx, cy, cz, cw, slice, iterations, bailout, 0);
}

// The orbit trap of the same iteration, for `.color(orbit_trap(...))`.
real julia_orbit_trap(vec3 p, real cx, real cy, real cz, real cw, real slice, int iterations, real bailout, int kind) {
    orbit_trap trap = orbit_trap_start();
    julia_orbit(p, cx, cy, cz, cw, slice, iterations, bailout, &trap);
    return orbit_trap_value(trap, kind);
}

// A sphere holding every point where the DE can be <= 0. With
// R = (1 + sqrt(1 + 4|c|)) / 2, the root of R^2 - R = |c| (so R >= 1): if
// |q| > R then |q^2 + c| >= |q|^2 - |c| > |q|, so |q| grows, never reaches
// 0 (dr > 0) and ends above 1: DE > 0. |q|^2 = |p|^2 + slice^2, so that
// holds for |p| > sqrt(R^2 - slice^2). If |slice| >= R the slice is empty:
// the radius is then -1, and the sphere distance |p| + 1 (a lower bound on
// the distance to nothing) never reaches a hit.
real julia_bound_radius(real cx, real cy, real cz, real cw, real slice, int iterations, real bailout) {
    real c = sqrt(cx * cx + cy * cy + cz * cz + cw * cw);
    real radius = 0.5f * (1.0f + sqrt(1.0f + 4.0f * c));
    real squared = radius * radius - slice * slice;
    return SELECT((real)-1.0f, sqrt(max(squared, 0.0f)), squared > 0.0f);
}
