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
