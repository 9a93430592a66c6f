// Quilez's quadratic polynomial smooth minimum (LANGUAGE.md, "Smooth
// combinations"): h = max(k - |a - b|, 0) / k, smin = min(a, b) - h^2 k / 4.
// k = 0 (a param may reach it) is the plain minimum, not 0 / 0.
real smooth_min(real a, real b, real k) {
    real h = max(k - fabs(a - b), 0.0f) / max(k, (real)1e-30f);
    return min(a, b) - h * h * k * 0.25f;
}

real smooth_max(real a, real b, real k) {
    return -smooth_min(-a, -b, k);
}
