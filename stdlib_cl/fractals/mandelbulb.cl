// The Mandelbulb (White and Nylander's power-n "triplex" z -> z^n + p) and
// its distance estimate DE = 0.5 ln(r) r / dr with the analytic running
// scalar derivative dr -> n r^(n-1) dr + 1: Syntopia, "Distance Estimated 3D
// Fractals", parts IV and V; the formulas of LANGUAGE.md, "Fractals".
//
// Overflow, so that the estimate stays finite for every valid argument:
// - r^power is at most 1e12 on a step that keeps iterating. A step whose
//   r^power exceeds it escapes: the new z and dr are stored divided by
//   r^power, whose logarithm goes to `log_scale`; the final
//   DE = 0.5 (log_scale + ln|z|) |z| / dr is then the same number.
//   (An orbit passing |z| ~ 1e12 is treated as escaped even if the bailout
//   is larger than that.)
// - dr is capped at 1e24 (only orbits that stay bounded get there, whose
//   DE is then below 1e-20 either way), so n r^(n-1) dr stays below 1e38.

// The direction of the triplex power z^power: the spherical angles of z
// (theta from the z axis, 0 at r = 0; phi about it) times the power.
vec3 mandelbulb_direction(vec3 z, real r, real power) {
    real theta = SELECT(acos(clamp(z.z / r, -1.0f, 1.0f)), (real)0.0f, r == 0.0f) * power;
    real phi = atan2(z.y, z.x) * power;
    real cos_theta, cos_phi;
    real sin_theta = sincos(theta, &cos_theta), sin_phi = sincos(phi, &cos_phi);
    return v3(sin_theta * cos_phi, sin_phi * sin_theta, cos_theta);
}

// z^8 without trigonometry, after Quilez ("Mandelbulb", 2009), with his
// polar axis y turned to our z: the same value as r^8 times the direction
// at power 8 (to rounding), for a fraction of the cost. On the z axis
// (x = y = 0) the polynomial is 0 / 0; there z^8 = (0, 0, z^8).
vec3 mandelbulb_power8(vec3 z) {
    real x = z.y, y = z.z, w = z.x;                  // Quilez's x, y, z
    real x2 = x * x, y2 = y * y, w2 = w * w;
    real x4 = x2 * x2, y4 = y2 * y2, w4 = w2 * w2;
    real k3 = x2 + w2;
    real k2 = rsqrt(k3 * k3 * k3 * k3 * k3 * k3 * k3);
    real k1 = x4 + y4 + w4 - 6.0f * y2 * w2 - 6.0f * x2 * y2 + 2.0f * w2 * x2;
    real k4 = x2 - y2 + w2;
    vec3 power8 = v3(-8.0f * y * k4 * (x4 * x4 - 28.0f * x4 * x2 * w2 + 70.0f * x4 * w4 - 28.0f * x2 * w2 * w4 + w4 * w4) * k1 * k2,
                     64.0f * x * y * w * (x2 - w2) * k4 * (x4 - 6.0f * x2 * w2 + w4) * k1 * k2,
                     -16.0f * y2 * k3 * k4 * k4 + k1 * k1);
    real z8 = y4 * y4;
    return v3_select(power8, v3((real)0.0f, 0.0f, z8), k3 == 0.0f);
}

// The iteration, recording its orbit in `trap`.
real mandelbulb_orbit(vec3 p, real power, int iterations, real bailout, orbit_trap *trap) {
    vec3 z = p;
    real dr = 1.0f;
    real log_scale = 0.0f;
    mask active = MASK_TRUE;
    for (int i = 0; i < iterations; i++) {
        real r = v3_length(z);
        active = active & (r <= bailout);
        if (!ANY(active)) break;
        vec3 z_power;       // the triplex power z^power: r^power times a direction
        real r_power1;      // r^(power-1)
        if (ALL(power == 8.0f)) {
            // power is uniform (a literal or a param): the same branch in every lane
            z_power = mandelbulb_power8(z);
            real r2 = r * r;
            r_power1 = r2 * r2 * r2 * r;
        } else {
            // r^power as exp(power ln r): pow costs ~10x exp + log on vector
            // lanes (PoCL); 0^0 = 1 at power 1.
            real log_r = log(r);
            z_power = v3_scale(mandelbulb_direction(z, r, power), exp(power * log_r));
            r_power1 = SELECT(exp((power - 1.0f) * log_r), (real)1.0f, power == 1.0f);
        }
        real r_power = r_power1 * r;
        // z = r^power direction + p, dr = power r^(power-1) dr + 1 ...
        vec3 z_next = v3_add(z_power, p);
        real dr_next = min(power * r_power1 * dr + 1.0f, 1e24f);
        // ... or both divided by r^power when that is too large.
        mask escapes = active & (r_power > 1e12f);
        if (ANY(escapes)) {
            real log_power = power * log(r);
            real inverse = exp(-log_power);
            vec3 direction = mandelbulb_direction(z, r, power);
            z_next = v3_select(z_next, v3_add(direction, v3_scale(p, inverse)), escapes);
            dr_next = SELECT(dr_next, power * dr / r + inverse, escapes);
            log_scale = SELECT(log_scale, log_power, escapes);
        }
        z = v3_select(z, z_next, active);
        dr = SELECT(dr, dr_next, active);
        orbit_trap_add(trap, z, active & !escapes);
        active = active & !escapes;
    }
    real r = v3_length(z);
    real de = 0.5f * (log(r) + log_scale) * r / dr;
    // DE = 0 at r = 0; min() keeps it finite where |p| overflows (> 1e19 in float).
    return SELECT(min(de, 1e30f), (real)0.0f, r == 0.0f);
}

//: fractal mandelbulb(power: num = 8 1..32, iterations: int = 12 1..1000, bailout: num = 2 >0)
real de_mandelbulb(vec3 p, real power, int iterations, real bailout) {
    return mandelbulb_orbit(p, power, iterations, bailout, 0);
}

// The orbit trap of the same iteration, for `.color(orbit_trap(...))`.
real mandelbulb_orbit_trap(vec3 p, real power, int iterations, real bailout, int kind) {
    orbit_trap trap = orbit_trap_start();
    mandelbulb_orbit(p, power, iterations, bailout, &trap);
    return orbit_trap_value(trap, kind);
}

// A sphere holding every point where the DE can be <= 0, i.e. where the
// final |z| can be <= 1. Let R = |p| with R^(power-1) >= 2 (so R > 1). If
// |z| >= R then |z^power + p| >= |z|^power - R >= 2|z| - R >= |z|: |z| never
// falls below R > 1, so the DE is > 0 for |p| >= 2^(1/(power-1)). Power 1 is
// z -> z + p, z_n = (n+1) p, and |p| > 1 suffices. Near power 1 the radius
// grows without bound (+inf in float: no bound).
real mandelbulb_bound_radius(real power, int iterations, real bailout) {
    return SELECT(pow((real)2.0f, 1.0f / (power - 1.0f)), (real)1.0f, power <= 1.0f);
}
