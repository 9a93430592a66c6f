// Where a ray crosses a bounding sphere (Hart et al. 1989: skip the empty
// space around a fractal). The span [enter, exit] of t with |o + t d - c| <=
// r, enter clamped to 0; the mask says whether the ray meets the sphere at
// t >= 0 at all (d is a unit vector).
mask ray_sphere_span(vec3 origin, vec3 dir, vec3 centre, real radius, real *enter, real *exit) {
    vec3 offset = v3_sub(origin, centre);
    real b = v3_dot(offset, dir);
    real c = v3_dot(offset, offset) - radius * radius;
    real discriminant = b * b - c;
    real root = sqrt(max(discriminant, 0.0f));
    *enter = max(-b - root, 0.0f);
    *exit = -b + root;
    return (discriminant >= 0.0f) & (*exit >= 0.0f);
}
