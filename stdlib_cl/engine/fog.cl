#if FEATURE_FOG
// Exponential fog over a ray's length t: its colour mixes toward the fog's
// by 1 - exp(-density t); a miss is infinitely far and shows the fog colour.
vec3 fogged(vec3 color, real t, mask hit) {
    real clear = SELECT((real)0.0f, exp(-FOG_DENSITY * t), hit);
    return v3_add(v3_scale(color, clear), v3_scale(v3(FOG_R, FOG_G, FOG_B), 1.0f - clear));
}
#endif
