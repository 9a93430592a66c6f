// The fixed ray-marching template (sphere tracing, Hart 1996).
// The generated code above this file defines:
//   real distance_estimate(vec3 p, PARAMS_SPACE scalar *params);
//   vec3 shade(vec3 p, vec3 normal, vec3 dir, real threshold, real steps, mask hit,
//              PARAMS_SPACE scalar *params);
//   real scene_bound(PARAMS_SPACE scalar *params, vec3 *centre);  (a bounded scene)
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
