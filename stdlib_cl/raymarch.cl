// The fixed ray-marching template (sphere tracing, Hart 1996).
// The generated code above this file defines:
//   real distance_estimate(vec3 p, __constant scalar *params);
//   vec3 shade(vec3 p, vec3 normal, vec3 dir, real threshold, real steps, mask hit,
//              __constant scalar *params);
//   real scene_bound(__constant scalar *params, vec3 *centre);  (a bounded scene)
//   vec3 shade_passes(..., shading_passes *passes);  (with the shading passes)
//   MAX_STEPS, MAX_DISTANCE, HIT_EPSILON (0 = pixel footprint), BACKGROUND,
//   LANES_X, LANES_Y, LANE_X, LANE_Y, the output's CHANNELS and each
//   channel's index CHANNEL_NAME (R, G, B, A, Z, N_X, ..., then the passes
//   asked for: P_X, DIFFUSE_R, AO, ...; fractalc/passes.py), and the
//   constants of the effects the scene uses.
// `#if FEATURE_...` blocks are resolved by the emitter: a scene's kernel holds
// only the effects it uses (the directives themselves are gone from it).

// Camera block (`camera` kernel argument), see LANGUAGE.md "Camera model".
#define CAMERA_POSITION 0
#define CAMERA_FORWARD 3
#define CAMERA_RIGHT 6
#define CAMERA_UP 9
#define CAMERA_TAN_HALF_FOV 12
#define CAMERA_APERTURE 13      // lens diameter (read only with depth of field)
#define CAMERA_FOCUS 14         // distance of the plane in focus, along forward
#define CAMERA_PROJECTION 15    // 0 pinhole, 1 fisheye, 2 equirectangular (program.PROJECTIONS)
#define CAMERA_FISHEYE_HALF_ANGLE 16   // radians from the centre to the top edge
#define CAMERA_STEREO 17        // 0 none, 1 side by side, 2 top and bottom (program.STEREO_LAYOUTS)
#define CAMERA_EYE_SEPARATION 18
#define CAMERA_SIZE 19
#define PROJECTION_FISHEYE 1
#define PROJECTION_EQUIRECTANGULAR 2
#define STEREO_SIDE_BY_SIDE 1
#define STEREO_TOP_BOTTOM 2
#define PI_F 3.14159265358979323846f

// Hart's clarity function: the hit threshold grows with t by the angle one
// pixel subtends, or stays the scene's constant epsilon.
#if HIT_EPSILON_IS_PIXEL
#define HIT_THRESHOLD(t, pixel_angle) max((t) * ((pixel_angle) * EPSILON_SCALE), SCALAR_MIN_EPSILON)
#else
#define HIT_THRESHOLD(t, pixel_angle) (HIT_EPSILON * EPSILON_SCALE)
#endif
real hit_threshold(real t, scalar pixel_angle) {
    return (real)HIT_THRESHOLD(t, pixel_angle);
}

typedef struct {
    real t;        // ray distance of the hit
    mask hit;
    real steps;    // distance evaluations taken
    real d;        // the distance estimate at t where the lane hit (forward normals reuse it; else 0)
#if FEATURE_GLOW
    real closest;  // the smallest distance estimate along the ray
#endif
} march_result;

#if FEATURE_CONE
// Cone marching hands a packet over to its rays where the distance at its
// axis falls below CONE_STOP times its spread.
#define CONE_STOP 2.0f

// Reductions over the lanes of a work-item (its packet of rays).
scalar lanes_sum(real v) {
    scalar lanes[LANES];
    STORE_LANES(v, 0, lanes);
    scalar sum = lanes[0];
    for (int i = 1; i < LANES; i++)
        sum += lanes[i];
    return sum;
}

scalar lanes_max(real v) {
    scalar lanes[LANES];
    STORE_LANES(v, 0, lanes);
    scalar most = lanes[0];
    for (int i = 1; i < LANES; i++)
        most = max(most, lanes[i]);
    return most;
}

// Cone marching of a packet (cone tracing, Amanatides 1984, marched as the
// demoscene does): one distance at the packet's axis point c(t) = o + t d
// (o, d: the mean origin and direction of its rays) bounds the distance at
// each ray's point at t, which lies within spread(t) = max |o_i - o| +
// t max |d_i - d| of c(t); while d(c) > spread, every ray may go on by
// d(c) - spread. Where d(c) < CONE_STOP spread (the cone could step only
// a little) the rays are marched one by one from the t reached: far from
// the surface, one evaluation instead of one per ray and step. The axis
// point is one point for all lanes, so it is evaluated with scalar
// arithmetic (`uniform_distance_estimate`, the scene's estimate in scalar
// types): a fraction of a vector step's cost. `t_enter`, `t_exit`: where
// each ray's marching may start and must end; `steps`: the cone's steps,
// which are its rays' first march steps (each ray's steps, max_steps
// included, count them).
real cone_start(vec3 origin, vec3 dir, mask active, real t_enter, real t_exit, scalar pixel_angle,
                int *steps, __constant scalar *params) {
    *steps = 0;
    if (!ANY(active))
        return t_enter;
    real weight = SELECT((real)0.0f, (real)1.0f, active);
    scalar share = 1.0f / lanes_sum(weight);
    uvec3 o = uniform_v3(share * lanes_sum(weight * origin.x), share * lanes_sum(weight * origin.y),
                         share * lanes_sum(weight * origin.z));
    uvec3 d = uniform_v3(share * lanes_sum(weight * dir.x), share * lanes_sum(weight * dir.y),
                         share * lanes_sum(weight * dir.z));
    vec3 axis_origin = v3((real)o.x, (real)o.y, (real)o.z), axis_dir = v3((real)d.x, (real)d.y, (real)d.z);
    real own_origin = v3_length(v3_sub(origin, axis_origin)), own_dir = v3_length(v3_sub(dir, axis_dir));
    scalar spread_origin = lanes_max(weight * own_origin), spread_dir = lanes_max(weight * own_dir);
    scalar t = -lanes_max(SELECT((real)-MAX_DISTANCE, -t_enter, active));
    scalar t_last = lanes_max(SELECT((real)0.0f, t_exit, active));
    // over-relaxed as the rays are, with the same fallback
    scalar omega = 1.0f, previous_clear = 0.0f, step = 0.0f;
#if FEATURE_OVERRELAX
    omega = OVERRELAX;
#endif
    scalar distance = 0.0f, t_evaluated = -1.0f;
    for (int i = 0; i < MAX_STEPS && t < t_last; i++) {
#if FEATURE_COUNT
        count_evaluations(COUNT_CAMERA, (LANE_X == 0.0f) & (LANE_Y == 0.0f), 1.0f, params);
#endif
        distance = uniform_distance_estimate(uniform_v3_add(o, uniform_v3_scale(d, t)), params);
        t_evaluated = t;
        *steps = i + 1;
        // the radius of the empty ball about every ray's point at t
        scalar clear = distance - (spread_origin + t * spread_dir);
        if (omega > 1.0f && clear + previous_clear < step) {
            t -= step;
            clear = previous_clear;
            omega = 1.0f;
        }
        // (not below the rays' hit threshold: a cone from one point, with no
        // spread, would otherwise creep towards the surface)
        if (clear <= max((CONE_STOP - 1.0f) * (spread_origin + t * spread_dir), HIT_THRESHOLD(t, pixel_angle)))
            break;
        previous_clear = clear;
        step = omega * clear;
        t += step;
    }
    // where the last ball still holds the point of t: it reaches further
    // along the rays nearer the axis (each within its own spread of it),
    // but not where it is within the hit threshold (a camera that close to
    // a surface hits at t = 0, as one ray's march has it)
    real further = (real)0.0f;
    if (t_evaluated == t) {
        real own_clear = (real)distance - (own_origin + (real)t * own_dir);
        further = SELECT((real)0.0f, own_clear, own_clear > (real)HIT_THRESHOLD(t, pixel_angle));
    }
    return (real)t + further;
}
#endif

// Sphere tracing of LANES rays at once; a lane stops on a hit (distance
// below the threshold, or <= 0 at the start: a camera inside a solid hits at
// t = 0), past MAX_DISTANCE, or after MAX_STEPS. `jitter` in [0, 1) shortens
// the first step by that fraction (dithering against banding, Syntopia part
// II: steps and glow then vary smoothly between neighbouring pixels). A
// `packet` of rays (the camera's, uniform) is cone-marched first.
march_result march_rays(vec3 origin, vec3 dir, mask active, scalar pixel_angle, real jitter, int packet,
                        __constant scalar *params) {
    march_result r;
    r.t = 0.0f;
    r.hit = (mask)0;
    r.steps = 0.0f;
    r.d = 0.0f;
#if FEATURE_GLOW
    r.closest = (real)MAX_DISTANCE;
#endif
#if FEATURE_OVERRELAX
    // Over-relaxed sphere tracing (Keinert et al. 2014): steps of
    // OVERRELAX * d while successive unbounding spheres overlap; when they
    // do not, the lane steps back and marches plainly from there on.
    real omega = (real)OVERRELAX;
    real previous_radius = 0.0f, step = 0.0f;
#endif
#if FEATURE_SCENE_BOUND
    // Rays start where they enter the scene's bounding sphere and miss once
    // they leave it: the empty space around the scene costs no evaluation.
    real t_exit;
    vec3 centre;
    real radius = scene_bound(params, &centre);
    // widened by the hit threshold at its far side: rays that pass within
    // the threshold of the scene hit it, bound or not
    radius = radius + hit_threshold(v3_length(v3_sub(origin, centre)) + radius, pixel_angle);
    mask in_bound = ray_sphere_span(origin, dir, centre, radius, &r.t, &t_exit);
#if FEATURE_SCENE_HALF_SPACES
    // The scene's ground half-spaces lie outside the sphere: a ray that may
    // meet one is marched from its start to MAX_DISTANCE, as unbounded.
    mask clear = clear_of_half_spaces(origin, dir, hit_threshold(0.0f, pixel_angle), params);
    r.t = SELECT((real)0.0f, r.t, clear);
    t_exit = SELECT((real)MAX_DISTANCE, t_exit, clear);
    in_bound = in_bound | !clear;
#endif
    active = active & in_bound;
#endif
    int first_step = 0;     // a ray's steps before its own: its cone's
#if FEATURE_CONE
    if (packet) {
        int cone_steps;
        real t_last = (real)MAX_DISTANCE;
#if FEATURE_SCENE_BOUND
        t_last = t_exit;
#endif
        r.t = max(r.t, cone_start(origin, dir, active, r.t, t_last, pixel_angle, &cone_steps, params));
        r.steps = SELECT((real)0.0f, (real)cone_steps, active);
        first_step = cone_steps;
        active = active & (r.t <= t_last);
    }
#endif
    for (int i = first_step; i < MAX_STEPS && ANY(active); i++) {
#if FEATURE_COUNT
        count_evaluations(march_purpose(params), active, 1.0f, params);
#endif
        real d = distance_estimate(v3_add(origin, v3_scale(dir, r.t)), params);
        r.steps = r.steps + SELECT((real)0.0f, (real)1.0f, active);
#if FEATURE_OVERRELAX
        // a long step that lands inside a solid (d < 0) overshot too
        mask overshot = active & (omega > 1.0f) & ((fabs(d) + previous_radius < step) | (d < 0.0f));
        if (ANY(overshot)) {
            // back to the previous point (its distance was previous_radius),
            // to step plainly from there
            r.t = SELECT(r.t, r.t - step, overshot);
            d = SELECT(d, previous_radius, overshot);
            omega = SELECT(omega, (real)1.0f, overshot);
        }
        previous_radius = fabs(d);
#endif
#if FEATURE_GLOW
        r.closest = SELECT(r.closest, min(r.closest, d), active);
#endif
        mask close = (d < hit_threshold(r.t, pixel_angle)) | (d <= 0.0f);
        r.hit = r.hit | (active & close);
#if FEATURE_FORWARD_NORMALS
        r.d = SELECT(r.d, d, active & close);
#endif
        active = active & !close;
#if FEATURE_DITHER
        if (i == first_step)
            d = d * (1.0f - jitter);
#endif
#if FEATURE_OVERRELAX
        step = d * omega;
        r.t = SELECT(r.t, r.t + step, active);
#else
        r.t = SELECT(r.t, r.t + d, active);
#endif
        active = active & (r.t < (real)MAX_DISTANCE);
#if FEATURE_SCENE_BOUND
        active = active & (r.t <= t_exit);
#endif
    }
    return r;
}

march_result march(vec3 origin, vec3 dir, mask active, scalar pixel_angle, real jitter,
                   __constant scalar *params) {
    return march_rays(origin, dir, active, pixel_angle, jitter, 0, params);
}

// The camera's rays through a work-item's pixels: a packet.
march_result march_camera(vec3 origin, vec3 dir, mask active, scalar pixel_angle, real jitter,
                          __constant scalar *params) {
    return march_rays(origin, dir, active, pixel_angle, jitter, 1, params);
}

vec3 camera_axis(__constant scalar *camera, int first) {
    return v3(camera[first], camera[first + 1], camera[first + 2]);
}

// The world direction of (x, y, z) in the camera's frame: right, up', forward.
vec3 camera_ray(__constant scalar *camera, real x, real y, real z) {
    return v3_add(v3_scale(camera_axis(camera, CAMERA_FORWARD), z),
                  v3_add(v3_scale(camera_axis(camera, CAMERA_RIGHT), x), v3_scale(camera_axis(camera, CAMERA_UP), y)));
}

// The height in pixels of one eye's image.
int eye_height(__constant scalar *camera, int height) {
    return (int)camera[CAMERA_STEREO] == STEREO_TOP_BOTTOM ? height / 2 : height;
}

// The angle one pixel subtends at the image centre (Hart's clarity function).
scalar camera_pixel_angle(__constant scalar *camera, int height) {
    int projection = (int)camera[CAMERA_PROJECTION];
    scalar across_height = projection == PROJECTION_FISHEYE ? 2.0f * camera[CAMERA_FISHEYE_HALF_ANGLE]
                         : projection == PROJECTION_EQUIRECTANGULAR ? PI_F : 2.0f * camera[CAMERA_TAN_HALF_FOV];
    return across_height / (scalar)eye_height(camera, height);
}

// The ray through sub-pixel position (px, py) (pixel units, from the
// top-left): its direction, its start in `origin`, and in `seen` whether the
// projection has a ray there (not outside a fisheye's 360 degrees). A stereo
// image holds the left eye's image in its left (top) half and the right
// eye's in the other; the eyes sit half the eye separation either side of
// the camera along right: a pinhole eye aims at the point its ray through
// the camera position meets on the plane in focus (no parallax there), a
// fisheye eye looks parallel (VR180), and an equirectangular pair is
// omni-directional stereo: each ray starts on the circle of the eyes,
// across the view direction of its column.
vec3 pixel_ray(__constant scalar *camera, int width, int height, real px, real py, vec3 *origin, mask *seen) {
    int stereo = (int)camera[CAMERA_STEREO];
    scalar w = (scalar)width, h = (scalar)eye_height(camera, height);
    real eye = 0.0f;     // -1 left, 1 right, 0 no stereo
    if (stereo == STEREO_SIDE_BY_SIDE) {
        w = 0.5f * (scalar)width;
        eye = SELECT((real)-1.0f, (real)1.0f, px >= (real)w);
        px = SELECT(px, px - w, px >= (real)w);
    } else if (stereo == STEREO_TOP_BOTTOM) {
        eye = SELECT((real)-1.0f, (real)1.0f, py >= (real)h);
        py = SELECT(py, py - h, py >= (real)h);
    }
    // the image position: a to the right, b up, in units of half the eye's height
    real a = (2.0f * px - w) / h, b = (h - 2.0f * py) / h;
    int projection = (int)camera[CAMERA_PROJECTION];
    vec3 position = camera_axis(camera, CAMERA_POSITION);
    vec3 eye_offset = v3_scale(camera_axis(camera, CAMERA_RIGHT), 0.5f * camera[CAMERA_EYE_SEPARATION] * eye);
    *seen = MASK_TRUE;
    vec3 dir;
    if (projection == PROJECTION_FISHEYE) {
        // equidistant: the angle from forward grows with the distance from the centre
        real rho = sqrt(a * a + b * b);
        real theta = rho * camera[CAMERA_FISHEYE_HALF_ANGLE];
        real across = sin(theta) / max(rho, (real)1e-30f);
        dir = v3_normalize(camera_ray(camera, a * across, b * across, cos(theta)));
        *seen = theta <= (real)PI_F;
    } else if (projection == PROJECTION_EQUIRECTANGULAR) {
        // longitude from -180 (left edge) to 180 degrees, latitude 90 (top) to -90
        real longitude = PI_F * a * (h / w), latitude = 0.5f * PI_F * b;
        dir = camera_ray(camera, cos(latitude) * sin(longitude), sin(latitude), cos(latitude) * cos(longitude));
        // omni-directional stereo: the eye on the circle, across this column's view
        eye_offset = v3_scale(camera_ray(camera, cos(longitude), 0.0f, -sin(longitude)),
                              0.5f * camera[CAMERA_EYE_SEPARATION] * eye);
    } else {
        scalar tan_half_fov = camera[CAMERA_TAN_HALF_FOV];
        dir = v3_normalize(camera_ray(camera, a * tan_half_fov, b * tan_half_fov, 1.0f));
        if (stereo) {
            // toward where the centre's ray meets the plane in focus
            real reach = camera[CAMERA_FOCUS] / v3_dot(dir, camera_axis(camera, CAMERA_FORWARD));
            dir = v3_normalize(v3_sub(v3_scale(dir, reach), eye_offset));
        }
    }
    *origin = v3_add(position, eye_offset);
    return dir;
}

#if FEATURE_DEPTH_OF_FIELD
// Thin-lens depth of field: the ray starts at a uniform point (u, v in
// [0, 1)) of the lens disc and passes through the point its pinhole ray
// meets in focus: on the plane at the focus distance along forward (a
// pinhole camera), or at that distance along the ray (the disc then faces
// the ray: fisheye and equirectangular cameras see all around).
void lens_sample(__constant scalar *camera, real u, real v, vec3 *origin, vec3 *dir) {
    vec3 forward = camera_axis(camera, CAMERA_FORWARD);
    vec3 right = camera_axis(camera, CAMERA_RIGHT);
    vec3 up = camera_axis(camera, CAMERA_UP);
    real reach = camera[CAMERA_FOCUS] / v3_dot(*dir, forward);
    if ((int)camera[CAMERA_PROJECTION] != 0) {
        reach = (real)camera[CAMERA_FOCUS];
        // a frame across the ray: right' horizontal where the ray is not vertical
        vec3 across = v3(dir->y * up.z - dir->z * up.y, dir->z * up.x - dir->x * up.z, dir->x * up.y - dir->y * up.x);
        vec3 fallback = v3_select(across, right, v3_dot(across, across) < 1e-12f);
        right = v3_normalize(fallback);
        up = v3(right.y * dir->z - right.z * dir->y, right.z * dir->x - right.x * dir->z,
                right.x * dir->y - right.y * dir->x);
    }
    vec3 focus = v3_add(*origin, v3_scale(*dir, reach));
    real radius = 0.5f * camera[CAMERA_APERTURE] * sqrt(u);
    real angle = 6.283185307179586f * v;
    *origin = v3_add(*origin, v3_add(v3_scale(right, radius * cos(angle)), v3_scale(up, radius * sin(angle))));
    *dir = v3_normalize(v3_sub(focus, *origin));
}
#endif

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

// A per-lane hash (PCG), for stratified jitter that is the same on every run.
lane_uint hash_lanes(lane_uint v) {
    lane_uint state = v * 747796405u + 2891336453u;
    lane_uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

real unit_random(lane_uint v) {
    return TO_REAL(hash_lanes(v) >> 8) * (1.0f / 16777216.0f);
}

// Stores one value per lane into `channel` of the block's pixels, `block`
// pointing at its top-left pixel in an image of rows of `pitch` pixels of
// CHANNELS floats (lane i is pixel (i % LANES_X, i / LANES_X) of the block).
void store_channel(lane_float v, int channel, __global float *block, int pitch) {
#if LANES == 1
    block[channel] = v;
#else
    float lanes[LANES];
    STORE_LANES(v, 0, lanes);
    for (int i = 0; i < LANES; i++)
        block[((i / LANES_X) * pitch + i % LANES_X) * CHANNELS + channel] = lanes[i];
#endif
}

// Stores a vector per lane into three consecutive channels from `first`.
void store_vec3(vec3 v, int first, __global float *block, int pitch) {
    store_channel(TO_FLOAT(v.x), first, block, pitch);
    store_channel(TO_FLOAT(v.y), first + 1, block, pitch);
    store_channel(TO_FLOAT(v.z), first + 2, block, pitch);
}

// The surface normal where a march hit (0 elsewhere).
vec3 hit_normal(vec3 origin, vec3 dir, march_result m, scalar pixel_angle, __constant scalar *params) {
    vec3 normal = v3((real)0.0f, 0.0f, 0.0f);
    if (ANY(m.hit)) {
        vec3 p = v3_add(origin, v3_scale(dir, m.t));
#if FEATURE_COUNT
        count_scope(m.hit, params);
#endif
        normal = v3_select(normal, estimate_hit_normal(p, m.d, hit_threshold(m.t, pixel_angle), params), m.hit);
    }
    return normal;
}

#if FEATURE_FOG
// Exponential fog over a ray's length t: its colour mixes toward the fog's
// by 1 - exp(-density t); a miss is infinitely far and shows the fog colour.
vec3 fogged(vec3 color, real t, mask hit) {
    real clear = SELECT((real)0.0f, exp(-FOG_DENSITY * t), hit);
    return v3_add(v3_scale(color, clear), v3_scale(v3(FOG_R, FOG_G, FOG_B), 1.0f - clear));
}
#endif

#if FEATURE_REFLECTIONS
// Mirror reflections, up to REFLECTIONS bounces (no recursion): each surface
// keeps (1 - reflectivity) of its own colour and passes reflectivity on to
// what its mirror direction sees; a bounce that misses sees the background
// (with fog: the fog, and what it hits is fogged along the bounce).
vec3 reflected_color(vec3 origin, vec3 dir, march_result m, vec3 normal, vec3 seen_first,
                     scalar pixel_angle, __constant scalar *params) {
    mask active = m.hit;
    vec3 p = v3_add(origin, v3_scale(dir, m.t));
    real threshold = hit_threshold(m.t, pixel_angle);
    real weight = 1.0f;
    vec3 seen_now = seen_first;
    vec3 color = v3((real)0.0f, 0.0f, 0.0f);
    for (int bounce = 0; bounce < REFLECTIONS; bounce++) {
        real reflectivity = SELECT((real)0.0f, surface_at(p, params).reflectivity, active);
        color = v3_add(color, v3_scale(seen_now, weight * (1.0f - reflectivity)));
        weight = weight * reflectivity;
        active = active & (reflectivity > 0.0f);
        if (!ANY(active))
            return color;
        dir = v3_sub(dir, v3_scale(normal, 2.0f * v3_dot(dir, normal)));
        vec3 start = v3_add(p, v3_scale(normal, 2.0f * threshold));
#if FEATURE_COUNT
        count_march_purpose(COUNT_REFLECTIONS, params);
#endif
        march_result b = march(start, dir, active, pixel_angle, 0.0f, params);
        normal = hit_normal(start, dir, b, pixel_angle, params);
        p = v3_add(start, v3_scale(dir, b.t));
        threshold = hit_threshold(b.t, pixel_angle);
        vec3 seen = background_seen(dir);
#if FEATURE_COUNT
        count_scope(b.hit, params);
#endif
        if (ANY(b.hit))
            seen = v3_select(seen, shade(p, normal, dir, threshold, b.steps, b.hit, params), b.hit);
#if FEATURE_FOG
        seen = fogged(seen, b.t, b.hit);     // the fog along the bounce
#endif
        seen_now = v3_select(seen_now, seen, active);
        active = active & b.hit;
    }
    return v3_add(color, v3_scale(seen_now, weight));
}
#endif

#if FEATURE_TRANSPARENCY
// Snell refraction of `dir` at a surface with `normal` facing it, for the
// ratio eta = n_from / n_to; under total internal reflection the ray goes on
// unbent (one transmission per ray, no internal bounces).
vec3 refracted(vec3 dir, vec3 normal, real eta) {
    real cos_in = -v3_dot(dir, normal);
    real k = 1.0f - eta * eta * (1.0f - cos_in * cos_in);
    vec3 bent = v3_add(v3_scale(dir, eta), v3_scale(normal, eta * cos_in - sqrt(max(k, 0.0f))));
    return v3_select(v3_normalize(bent), dir, k < 0.0f);
}

// Through a transparent solid entered at p (transparency as the dissertation
// plan asks, refraction as in Hong and Kook's ray tracer): the ray `dir`
// refracts in (ratio 1 / ior), marches inside to the far side and refracts
// out; returns the way out, and in *out_start where the ray goes on (lifted
// off the far side). Lanes not `active` are not marched.
vec3 through_solid(vec3 p, vec3 dir, vec3 normal, real ior, real threshold, mask active, vec3 *out_start,
                   __constant scalar *params) {
    vec3 inside_dir = refracted(dir, normal, 1.0f / ior);
    // Inside is where the distance is below the hit threshold, as at the hit
    // `p` itself. A signed distance is marched by the depth -d; the inside of
    // an escape-time fractal has no depth (its estimate is about 0 there),
    // so steps are at least `shortest`: the scene's bounding diameter fits
    // in MAX_STEPS of them. Gaps narrower than a step are passed over.
    real shortest = threshold;
#if FEATURE_SCENE_BOUND
    vec3 centre;
    shortest = max(shortest, 2.0f * scene_bound(params, &centre) / (real)MAX_STEPS);
#endif
    real t = 0.0f, t_inside = 0.0f;
    mask marching = active;
    for (int i = 0; i < MAX_STEPS && ANY(marching); i++) {
#if FEATURE_COUNT
        count_evaluations(COUNT_REFRACTION, marching, 1.0f, params);
#endif
        real d = distance_estimate(v3_add(p, v3_scale(inside_dir, t)), params);
        marching = marching & (d < threshold);
        t_inside = SELECT(t_inside, t, marching);
        t = SELECT(t, t + max(-d, shortest), marching);
        marching = marching & (t < (real)MAX_DISTANCE);
    }
    // the far side lies between the last point inside and the first one out
    for (int i = 0; i < 8; i++) {
        real middle = 0.5f * (t_inside + t);
#if FEATURE_COUNT
        count_evaluations(COUNT_REFRACTION, active, 1.0f, params);
#endif
        mask within = distance_estimate(v3_add(p, v3_scale(inside_dir, middle)), params) < threshold;
        t_inside = SELECT(t_inside, middle, within);
        t = SELECT(middle, t, within);
    }
    vec3 exit = v3_add(p, v3_scale(inside_dir, t));
#if FEATURE_COUNT
    count_scope(active, params);
    count_march_purpose(COUNT_REFRACTION, params);
#endif
    vec3 exit_normal = estimate_normal(exit, threshold, params);
    *out_start = v3_add(exit, v3_scale(exit_normal, 2.0f * threshold));
    return refracted(inside_dir, v3_scale(exit_normal, -1.0f), ior);
}

// Transparency: what the ray sees through the solid (through_solid) is
// mixed in by `transparency`.
vec3 transmitted_color(vec3 origin, vec3 dir, march_result m, vec3 normal, vec3 seen,
                       scalar pixel_angle, __constant scalar *params) {
    vec3 p = v3_add(origin, v3_scale(dir, m.t));
    surface s = surface_at(p, params);
    mask active = m.hit & (s.transparency > 0.0f);
    if (!ANY(active))
        return seen;
    vec3 out_start;
    vec3 out_dir = through_solid(p, dir, normal, s.ior, hit_threshold(m.t, pixel_angle), active, &out_start, params);
    march_result beyond = march(out_start, out_dir, active, pixel_angle, 0.0f, params);
    vec3 beyond_normal = hit_normal(out_start, out_dir, beyond, pixel_angle, params);
    vec3 far = background_seen(out_dir);
    if (ANY(beyond.hit)) {
#if FEATURE_COUNT
        count_scope(beyond.hit, params);
#endif
        vec3 q = v3_add(out_start, v3_scale(out_dir, beyond.t));
        far = v3_select(far, shade(q, beyond_normal, out_dir, hit_threshold(beyond.t, pixel_angle),
                                   beyond.steps, beyond.hit, params), beyond.hit);
    }
#if FEATURE_FOG
    far = fogged(far, beyond.t, beyond.hit);   // the fog beyond the solid
#endif
    real mixing = SELECT((real)0.0f, s.transparency, active);
    return v3_add(v3_scale(seen, 1.0f - mixing), v3_scale(far, mixing));
}
#endif

#if FEATURE_GLOW
// Glow, added after fog so that fog does not hide it: misses are lit by how
// close they passed to the surface (emission: it adds colour, not coverage).
vec3 glow_color(march_result m) {
    real glow = SELECT((real)0.0f, GLOW_STRENGTH * exp(-max(m.closest, 0.0f) / GLOW_RADIUS),
                       m.hit == (mask)0);
    return v3_scale(v3(GLOW_R, GLOW_G, GLOW_B), glow);
}
#endif

#if FEATURE_PATH_TRACE
// The path tracer's colour of one sample (stdlib_cl/pathtrace.cl, after this file).
vec3 path_color(vec3 origin, vec3 dir, march_result m, vec3 normal, scalar pixel_angle, lane_uint key,
                __constant scalar *params);
#endif

// Colour seen along one ray: the shaded surface or the background, then
// transparency, reflections, fog and glow.
vec3 trace_color(vec3 origin, vec3 dir, march_result m, vec3 normal, scalar pixel_angle,
                 __constant scalar *params) {
    vec3 color = background_seen(dir);
    if (ANY(m.hit)) {
        vec3 p = v3_add(origin, v3_scale(dir, m.t));
        real threshold = hit_threshold(m.t, pixel_angle);
#if FEATURE_COUNT
        count_scope(m.hit, params);
#endif
        color = v3_select(color, shade(p, normal, dir, threshold, m.steps, m.hit, params), m.hit);
    }
#if FEATURE_TRANSPARENCY
    color = transmitted_color(origin, dir, m, normal, color, pixel_angle, params);
#endif
#if FEATURE_REFLECTIONS
    color = reflected_color(origin, dir, m, normal, color, pixel_angle, params);
#endif
#if FEATURE_FOG
    color = fogged(color, m.t, m.hit);
#endif
#if FEATURE_TRANSPARENT_BACKGROUND
    // a miss is empty (zero colour and, in the kernel, zero coverage), fog
    // or no fog: RGB is premultiplied by the coverage
    color = v3_select(v3((real)0.0f, 0.0f, 0.0f), color, m.hit);
#endif
#if FEATURE_GLOW
    color = v3_add(color, glow_color(m));
#endif
    return color;
}

// Renders one tile. Work-item (gx, gy) covers the block of LANES_X x LANES_Y
// pixels whose top-left pixel is (x0 + gx * LANES_X, y0 + gy * LANES_Y)
// (compact blocks keep a work-item's rays alike, so its lanes diverge less
// than a row of LANES would). `out`: the whole image, whatever the tile:
// rows of `pitch` pixels of CHANNELS floats (R G B A Z N.x N.y N.z steps,
// then the passes asked for),
// pixel (x, y) at (y * pitch + x) * CHANNELS; pitch >= width and its row
// count >= height are multiples of LANES_X and LANES_Y (blocks past the
// image's edge write there).
__kernel VECTOR_LANES_HINT void render(__global float *out, __constant scalar *params,
                     __constant scalar *camera, int width, int height,
                     int x0, int y0, int pitch, int samples, uint seed) {
    int gx = get_global_id(0), gy = get_global_id(1);
    int block_x = x0 + gx * LANES_X, block_y = y0 + gy * LANES_Y;
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
    mask seen;       // not outside a fisheye's 360 degrees
    vec3 dir = pixel_ray(camera, width, height, px + 0.5f, py + 0.5f, &origin, &seen);
#if FEATURE_COUNT
    count_march_purpose(COUNT_CAMERA, params);
#endif
    march_result centre = march_camera(origin, dir, inside & seen, pixel_angle, jitter, params);
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
        // Stratified: a columns x rows array of cells covering the pixel,
        // one jittered sample per cell (square counts fill every cell).
        int columns = (int)ceil(sqrt((float)samples));
        int rows = (samples + columns - 1) / columns;
        color = v3((real)0.0f, 0.0f, 0.0f);
        coverage = 0.0f;
        for (int s = 0; s < samples; s++) {
            lane_uint key = hash_lanes(pixel_id * (uint)samples + (uint)s) ^ seed;
            real jx = ((real)(s % columns) + unit_random(key)) / (scalar)columns;
            real jy = ((real)(s / columns) + unit_random(key ^ 0x9e3779b9u)) / (scalar)rows;
            vec3 sample_origin;
            mask sample_seen;
            vec3 sample_dir = pixel_ray(camera, width, height, px + jx, py + jy, &sample_origin, &sample_seen);
#if FEATURE_DEPTH_OF_FIELD
            lens_sample(camera, unit_random(key ^ 0x85ebca6bu), unit_random(key ^ 0xc2b2ae35u),
                        &sample_origin, &sample_dir);
#endif
#if FEATURE_COUNT
            count_march_purpose(COUNT_CAMERA, params);
#endif
            march_result m = march_camera(sample_origin, sample_dir, inside & sample_seen, pixel_angle, jitter, params);
            vec3 sample_normal = hit_normal(sample_origin, sample_dir, m, pixel_angle, params);
#if FEATURE_PATH_TRACE
            color = v3_add(color, path_color(sample_origin, sample_dir, m, sample_normal, pixel_angle, key, params));
#else
            color = v3_add(color, trace_color(sample_origin, sample_dir, m, sample_normal, pixel_angle, params));
#endif
            coverage = coverage + SELECT((real)0.0f, (real)1.0f, m.hit);
        }
        color = v3_scale(color, (real)(1.0f / (scalar)samples));
        coverage = coverage * (real)(1.0f / (scalar)samples);
    }

    // glow, fog and background colours are bounded only below: their sums
    // may pass float's range (inf, or NaN where one meets 0); pixels stay finite
    color = v3(fmin(color.x, (real)FLT_MAX), fmin(color.y, (real)FLT_MAX), fmin(color.z, (real)FLT_MAX));
    __global float *block = out + (block_y * pitch + block_x) * CHANNELS;
    real depth = SELECT((real)INFINITY, centre.t, centre.hit);
    store_channel(TO_FLOAT(color.x), CHANNEL_R, block, pitch);
    store_channel(TO_FLOAT(color.y), CHANNEL_G, block, pitch);
    store_channel(TO_FLOAT(color.z), CHANNEL_B, block, pitch);
    store_channel(TO_FLOAT(coverage), CHANNEL_A, block, pitch);
    store_channel(TO_FLOAT(depth), CHANNEL_Z, block, pitch);
    store_vec3(normal, CHANNEL_N_X, block, pitch);
    store_channel(TO_FLOAT(centre.steps), CHANNEL_STEPS, block, pitch);

    // The passes asked for, of the pixel-centre ray like the AOVs above
    // (0 where it missed).
#if FEATURE_PASS_P
    vec3 hit_point = v3_select(v3((real)0.0f, 0.0f, 0.0f), v3_add(origin, v3_scale(dir, centre.t)), centre.hit);
    store_vec3(hit_point, CHANNEL_P_X, block, pitch);
#endif
#if FEATURE_SHADING_PASSES
    shading_passes passes;
    passes.diffuse = v3((real)0.0f, 0.0f, 0.0f);
    passes.specular = v3((real)0.0f, 0.0f, 0.0f);
    passes.shadow = 0.0f;
    passes.occlusion = 0.0f;
#if FEATURE_COUNT
    count_scope(centre.hit, params);
#endif
    if (ANY(centre.hit))
        shade_passes(v3_add(origin, v3_scale(dir, centre.t)), normal, dir, hit_threshold(centre.t, pixel_angle),
                     centre.steps, centre.hit, params, &passes);
#endif
#if FEATURE_PASS_DIFFUSE
    store_vec3(v3_select(v3((real)0.0f, 0.0f, 0.0f), passes.diffuse, centre.hit), CHANNEL_DIFFUSE_R, block, pitch);
#endif
#if FEATURE_PASS_SPECULAR
    store_vec3(v3_select(v3((real)0.0f, 0.0f, 0.0f), passes.specular, centre.hit), CHANNEL_SPECULAR_R, block, pitch);
#endif
#if FEATURE_PASS_AO
    store_channel(TO_FLOAT(SELECT((real)0.0f, passes.occlusion, centre.hit)), CHANNEL_AO, block, pitch);
#endif
#if FEATURE_PASS_SHADOW
    store_channel(TO_FLOAT(SELECT((real)0.0f, passes.shadow, centre.hit)), CHANNEL_SHADOW, block, pitch);
#endif
#if FEATURE_PASS_GLOW
    vec3 glow = v3((real)0.0f, 0.0f, 0.0f);   // none in a scene without glow
#if FEATURE_GLOW
    glow = glow_color(centre);
#endif
    store_vec3(glow, CHANNEL_GLOW_R, block, pitch);
#endif
#if FEATURE_PASS_MATERIAL
    // the index of the hit's material (lower.py's Surface.material); -1 where the ray missed
    real material = (real)-1.0f;
    if (ANY(centre.hit))
        material = SELECT(material, surface_at(v3_add(origin, v3_scale(dir, centre.t)), params).material, centre.hit);
    store_channel(TO_FLOAT(material), CHANNEL_MATERIAL, block, pitch);
#endif
#if FEATURE_PASS_ALBEDO
    // the hit's material colour (a denoiser's guide); 0 where the ray missed
    vec3 albedo = v3((real)0.0f, 0.0f, 0.0f);
    if (ANY(centre.hit)) {
        surface s = surface_at(v3_add(origin, v3_scale(dir, centre.t)), params);
        albedo = v3_select(albedo, v3(s.red, s.green, s.blue), centre.hit);
    }
    store_vec3(albedo, CHANNEL_ALBEDO_R, block, pitch);
#endif
}
