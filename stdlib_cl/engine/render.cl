// The camera's rays through the centres of the pixels of the block whose
// top-left pixel is (block_x, block_y); `active`: those inside the image
// and seen.
vec3 block_centre_rays(__constant scalar *camera, int width, int height, int block_x, int block_y,
                       vec3 *origin, mask *active) {
    real px = (real)block_x + LANE_X;
    real py = (real)block_y + LANE_Y;
    mask seen;       // not outside a fisheye's 360 degrees
    vec3 dir = pixel_ray(camera, width, height, px + 0.5f, py + 0.5f, origin, &seen);
    *active = (px < (real)width) & (py < (real)height) & seen;
    return dir;
}

// Sample `s` of `samples` through the block's pixels (px, py: their
// top-left corners), stratified: a columns x rows array of cells covering
// the pixel, one jittered sample per cell (square counts fill every cell).
// `key`: the sample's hash, whose bits its random numbers are.
vec3 sample_ray(__constant scalar *camera, int width, int height, real px, real py, lane_uint pixel_id, int s,
                int samples, uint seed, vec3 *origin, mask *seen, lane_uint *key) {
    int columns = (int)ceil(sqrt((float)samples));
    int rows = (samples + columns - 1) / columns;
    *key = hash_lanes(pixel_id * (uint)samples + (uint)s) ^ seed;
    real jx = ((real)(s % columns) + unit_random(*key)) / (scalar)columns;
    real jy = ((real)(s / columns) + unit_random(*key ^ 0x9e3779b9u)) / (scalar)rows;
    vec3 dir = pixel_ray(camera, width, height, px + jx, py + jy, origin, seen);
#if FEATURE_DEPTH_OF_FIELD
    lens_sample(camera, unit_random(*key ^ 0x85ebca6bu), unit_random(*key ^ 0xc2b2ae35u), origin, &dir);
#endif
    return dir;
}

// One block's pixels: its camera rays (the centre's, and the samples'),
// their colour, the channels and the passes; with cone marching, the
// centre's rays are packet `packet` of `cones`.
void render_block(__global float *out, PARAMS_SPACE scalar *params, __constant scalar *camera, int width,
                  int height, int pitch, int samples, uint seed, int block_x, int block_y
#if FEATURE_CONE
                  , const cone_packets *cones, int packet
#endif
                  ) {
    real px = (real)block_x + LANE_X;
    real py = (real)block_y + LANE_Y;
    mask inside = (px < (real)width) & (py < (real)height);
    scalar pixel_angle = camera_pixel_angle(camera, height);

    lane_uint pixel_id = TO_UINT(py) * (uint)width + TO_UINT(px);
    real jitter = 0.0f;
#if FEATURE_DITHER
    jitter = DITHER * unit_random(hash_lanes(pixel_id) ^ seed);
#endif

    // The camera's ray through the pixel centre gives the AOVs.
    vec3 origin;
    mask active;
    vec3 dir = block_centre_rays(camera, width, height, block_x, block_y, &origin, &active);
    COUNT_MARCH(COUNT_CAMERA);
#if FEATURE_CONE
    march_result centre = march_camera(origin, dir, active, pixel_angle, jitter, params, cones, packet);
#else
    march_result centre = march(origin, dir, active, pixel_angle, jitter, params);
#endif
    vec3 normal = hit_normal(origin, dir, centre, pixel_angle, params);

    vec3 color;
    real coverage;   // the fraction of the pixel's samples that hit
#if FEATURE_DEPTH_OF_FIELD
    bool pinhole = false;   // every sample goes through the lens
#else
    bool pinhole = samples == 1;
#endif
#if FEATURE_PATH_TRACE
    pinhole = false;        // every sample traces a path of its own
#endif
    if (pinhole) {
        color = trace_color(origin, dir, centre, normal, pixel_angle, params);
        coverage = SELECT((real)0.0f, (real)1.0f, centre.hit);
    } else {
        color = v3((real)0.0f, 0.0f, 0.0f);
        coverage = 0.0f;
        for (int first = 0; first < samples; first += LANES) {
            int count = min(LANES, samples - first);
            vec3 sample_origin;
            mask sample_seen;
            lane_uint key;
#if FEATURE_CONE
            // the cones of these samples' packets, side by side
            cone_packets sample_cones;
            for (int s = first; s < first + count; s++) {
                vec3 sample_dir = sample_ray(camera, width, height, px, py, pixel_id, s, samples, seed,
                                             &sample_origin, &sample_seen, &key);
                real t_enter, t_exit;
                mask marched = march_span(sample_origin, sample_dir, inside & sample_seen, pixel_angle, params,
                                          &t_enter, &t_exit);
                cone_packet(sample_origin, sample_dir, marched, t_enter, t_exit, &sample_cones, s - first);
            }
            march_cones(&sample_cones, count, pixel_angle, params);
#endif
            for (int s = first; s < first + count; s++) {
                vec3 sample_dir = sample_ray(camera, width, height, px, py, pixel_id, s, samples, seed,
                                             &sample_origin, &sample_seen, &key);
                COUNT_MARCH(COUNT_CAMERA);
#if FEATURE_CONE
                march_result m = march_camera(sample_origin, sample_dir, inside & sample_seen, pixel_angle, jitter,
                                              params, &sample_cones, s - first);
#else
                march_result m = march(sample_origin, sample_dir, inside & sample_seen, pixel_angle, jitter, params);
#endif
                vec3 sample_normal = hit_normal(sample_origin, sample_dir, m, pixel_angle, params);
#if FEATURE_PATH_TRACE
                color = v3_add(color, path_color(sample_origin, sample_dir, m, sample_normal, pixel_angle, key, params));
#else
                color = v3_add(color, trace_color(sample_origin, sample_dir, m, sample_normal, pixel_angle, params));
#endif
                coverage = coverage + SELECT((real)0.0f, (real)1.0f, m.hit);
            }
        }
        color = v3_scale(color, (real)(1.0f / (scalar)samples));
        coverage = coverage * (real)(1.0f / (scalar)samples);
    }

    // glow, fog and background colours are bounded only below: their sums
    // may pass float's range (inf, or NaN where one meets 0); pixels stay finite
    color = v3(fmin(color.x, (real)FLT_MAX), fmin(color.y, (real)FLT_MAX), fmin(color.z, (real)FLT_MAX));
    block_pixels pixels;
    real depth = SELECT((real)INFINITY, centre.t, centre.hit);
    store_channel(TO_FLOAT(color.x), CHANNEL_R, &pixels);
    store_channel(TO_FLOAT(color.y), CHANNEL_G, &pixels);
    store_channel(TO_FLOAT(color.z), CHANNEL_B, &pixels);
    store_channel(TO_FLOAT(coverage), CHANNEL_A, &pixels);
    store_channel(TO_FLOAT(depth), CHANNEL_Z, &pixels);
    store_vec3(normal, CHANNEL_N_X, &pixels);
    store_channel(TO_FLOAT(centre.steps), CHANNEL_STEPS, &pixels);

    // The passes asked for, of the pixel-centre ray like the AOVs above
    // (0 where it missed).
#if FEATURE_PASS_P
    vec3 hit_point = v3_select(v3((real)0.0f, 0.0f, 0.0f), v3_add(origin, v3_scale(dir, centre.t)), centre.hit);
    store_vec3(hit_point, CHANNEL_P_X, &pixels);
#endif
#if FEATURE_SHADING_PASSES
    shading_passes passes;
    passes.diffuse = v3((real)0.0f, 0.0f, 0.0f);
    passes.specular = v3((real)0.0f, 0.0f, 0.0f);
    passes.shadow = 0.0f;
    passes.occlusion = 0.0f;
    COUNT_SCOPE(centre.hit);
    if (ANY(centre.hit))
        shade_passes(v3_add(origin, v3_scale(dir, centre.t)), normal, dir, hit_threshold(centre.t, pixel_angle),
                     centre.steps, centre.hit, params, &passes);
#endif
#if FEATURE_PASS_DIFFUSE
    store_vec3(v3_select(v3((real)0.0f, 0.0f, 0.0f), passes.diffuse, centre.hit), CHANNEL_DIFFUSE_R, &pixels);
#endif
#if FEATURE_PASS_SPECULAR
    store_vec3(v3_select(v3((real)0.0f, 0.0f, 0.0f), passes.specular, centre.hit), CHANNEL_SPECULAR_R, &pixels);
#endif
#if FEATURE_PASS_AO
    store_channel(TO_FLOAT(SELECT((real)0.0f, passes.occlusion, centre.hit)), CHANNEL_AO, &pixels);
#endif
#if FEATURE_PASS_SHADOW
    store_channel(TO_FLOAT(SELECT((real)0.0f, passes.shadow, centre.hit)), CHANNEL_SHADOW, &pixels);
#endif
#if FEATURE_PASS_GLOW
    vec3 glow = v3((real)0.0f, 0.0f, 0.0f);   // none in a scene without glow
#if FEATURE_GLOW
    glow = glow_color(centre);
#endif
    store_vec3(glow, CHANNEL_GLOW_R, &pixels);
#endif
#if FEATURE_PASS_MATERIAL
    // the index of the hit's material (lower.py's Surface.material); -1 where the ray missed
    real material = (real)-1.0f;
    if (ANY(centre.hit))
        material = SELECT(material, surface_at(v3_add(origin, v3_scale(dir, centre.t)), params).material, centre.hit);
    store_channel(TO_FLOAT(material), CHANNEL_MATERIAL, &pixels);
#endif
#if FEATURE_PASS_ALBEDO
    // the hit's material colour (a denoiser's guide); 0 where the ray missed
    vec3 albedo = v3((real)0.0f, 0.0f, 0.0f);
    if (ANY(centre.hit)) {
        surface s = surface_at(v3_add(origin, v3_scale(dir, centre.t)), params);
        albedo = v3_select(albedo, v3(s.red, s.green, s.blue), centre.hit);
    }
    store_vec3(albedo, CHANNEL_ALBEDO_R, &pixels);
#endif
    write_block(&pixels, out + (block_y * pitch + block_x) * CHANNELS, pitch);
}

// Renders one tile. Work-item (gx, gy) covers the block of LANES_X x LANES_Y
// pixels whose top-left pixel is (x0 + gx * LANES_X, y0 + gy * LANES_Y)
// (compact blocks keep a work-item's rays alike, so its lanes diverge less
// than a row of LANES would). With cone marching, the work-item of every
// LANES-th block of a row renders it and the LANES - 1 after it (those of
// the others return at once), their packets' cones marched side by side
// first. `out`: the whole image, whatever the tile: rows of `pitch` pixels
// of CHANNELS floats (R G B A Z N.x N.y N.z steps, then the passes asked
// for), pixel (x, y) at (y * pitch + x) * CHANNELS; pitch >= width and its
// row count >= height are multiples of LANES_X and LANES_Y (blocks past the
// image's edge write there).
__kernel VECTOR_LANES_HINT void render(__global float *out, PARAMS_SPACE scalar *params,
                     __constant scalar *camera, int width, int height,
                     int x0, int y0, int pitch, int samples, uint seed) {
    int gx = get_global_id(0), gy = get_global_id(1);
    int block_y = y0 + gy * LANES_Y;
#if FEATURE_CONE
    if (gx % LANES != 0)
        return;
    int count = min(LANES, (int)get_global_size(0) - gx);
    scalar pixel_angle = camera_pixel_angle(camera, height);
    cone_packets cones;
    for (int packet = 0; packet < count; packet++) {
        vec3 origin;
        mask active;
        vec3 dir = block_centre_rays(camera, width, height, x0 + (gx + packet) * LANES_X, block_y, &origin, &active);
        real t_enter, t_exit;
        active = march_span(origin, dir, active, pixel_angle, params, &t_enter, &t_exit);
        cone_packet(origin, dir, active, t_enter, t_exit, &cones, packet);
    }
    march_cones(&cones, count, pixel_angle, params);
    for (int packet = 0; packet < count; packet++)
        render_block(out, params, camera, width, height, pitch, samples, seed, x0 + (gx + packet) * LANES_X, block_y,
                     &cones, packet);
#else
    render_block(out, params, camera, width, height, pitch, samples, seed, x0 + gx * LANES_X, block_y);
#endif
}
