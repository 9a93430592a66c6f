#if FEATURE_ENVIRONMENT
#if ENVIRONMENT_MAP
// Each lane's entry `index` of a table (a gather).
real table_at(__constant float *table, lane_uint index) {
    uint indices[LANES];
    scalar values[LANES];
    STORE_LANES(index, 0, indices);
    for (int i = 0; i < LANES; i++)
        values[i] = table[indices[i]];
    return LOAD_LANES(0, values);
}

// The environment map's texel that a direction falls in: row 0 looks up
// (+z), columns run from longitude -180 degrees (about z, 0 along +x).
lane_uint map_texel(vec3 dir) {
    real longitude = atan2(dir.y, dir.x), colatitude = acos(clamp(dir.z, -1.0f, 1.0f));
    lane_uint column = TO_UINT(clamp((longitude + PI_F) * (MAP_WIDTH / (2.0f * PI_F)), 0.0f, MAP_WIDTH - 1.0f));
    lane_uint row = TO_UINT(clamp(colatitude * (MAP_HEIGHT / PI_F), 0.0f, MAP_HEIGHT - 1.0f));
    return row * (uint)MAP_WIDTH + column;
}
#endif

// The sky (render key environment, fractalc/pathtrace.py): an environment
// map's texel, or the horizon colour at the horizon, blending linearly in
// the height of the direction (z is up) to the zenith above and the ground
// below.
vec3 environment(vec3 dir) {
#if ENVIRONMENT_MAP
    lane_uint texel = 3u * map_texel(dir);
    return v3(table_at(ENVIRONMENT_TEXELS, texel), table_at(ENVIRONMENT_TEXELS, texel + 1u),
              table_at(ENVIRONMENT_TEXELS, texel + 2u));
#else
    real above = max(dir.z, 0.0f), below = max(-dir.z, 0.0f);
    vec3 horizon = v3(ENVIRONMENT_HORIZON_R, ENVIRONMENT_HORIZON_G, ENVIRONMENT_HORIZON_B);
    vec3 zenith = v3(ENVIRONMENT_ZENITH_R, ENVIRONMENT_ZENITH_G, ENVIRONMENT_ZENITH_B);
    vec3 ground = v3(ENVIRONMENT_GROUND_R, ENVIRONMENT_GROUND_G, ENVIRONMENT_GROUND_B);
    return v3_add(horizon, v3_add(v3_scale(v3_sub(zenith, horizon), above), v3_scale(v3_sub(ground, horizon), below)));
#endif
}
#endif

// What a ray that misses along `dir` sees: the environment's sky where the
// scene has one, else the background colour.
vec3 background_seen(vec3 dir) {
#if FEATURE_ENVIRONMENT
    return environment(dir);
#else
    return v3(BACKGROUND_R, BACKGROUND_G, BACKGROUND_B);
#endif
}
