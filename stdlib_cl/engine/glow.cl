#if FEATURE_GLOW
// Glow, added after fog so that fog does not hide it: misses are lit by how
// close they passed to the surface (emission: it adds colour, not coverage).
vec3 glow_color(march_result m) {
    real glow = SELECT((real)0.0f, GLOW_STRENGTH * exp(-max(m.closest, 0.0f) / GLOW_RADIUS),
                       m.hit == (mask)0);
    return v3_scale(v3(GLOW_R, GLOW_G, GLOW_B), glow);
}
#endif
