// Exact signed distances of the primitive shapes, after Quilez's
// "distance functions" catalogue and Hart 1996. A `//:` line declares the
// language-level signature that the checker reads (see fractalc/stdlib.py).

//: shape sphere(radius: num = 1 >0)
real sd_sphere(vec3 p, real radius) {
    return v3_length(p) - radius;
}

//: shape box(size: size = 1 >0)
real sd_box(vec3 p, vec3 size) {
    vec3 q = v3_sub(v3_abs(p), v3_scale(size, 0.5f));
    vec3 outside = v3(max(q.x, 0.0f), max(q.y, 0.0f), max(q.z, 0.0f));
    return v3_length(outside) + min(max(q.x, max(q.y, q.z)), 0.0f);
}

//: shape plane(normal: vec3 = (0, 0, 1) nonzero, offset: num = 0)
real sd_plane(vec3 p, vec3 normal, real offset) {
    return v3_dot(p, v3_normalize(normal)) - offset;
}

//: shape torus(major: num = 1 >0 <=1e18, minor: num = 0.25 >0 <=1e18)
real sd_torus(vec3 p, real major, real minor) {
    real ring = sqrt(p.x * p.x + p.y * p.y) - major;
    return sqrt(ring * ring + p.z * p.z) - minor;
}

//: shape cylinder(radius: num = 0.5 >0, height: num = 2 >0)
real sd_cylinder(vec3 p, real radius, real height) {
    real dx = sqrt(p.x * p.x + p.y * p.y) - radius;
    real dz = fabs(p.z) - 0.5f * height;
    real ox = max(dx, 0.0f), oz = max(dz, 0.0f);
    return min(max(dx, dz), 0.0f) + sqrt(ox * ox + oz * oz);
}

//: shape capsule(a: vec3 = (0, 0, -0.5) -1e18..1e18, b: vec3 = (0, 0, 0.5) -1e18..1e18, radius: num = 0.25 >0 <=1e18)
real sd_capsule(vec3 p, vec3 a, vec3 b, real radius) {
    vec3 pa = v3_sub(p, a), ba = v3_sub(b, a);
    real length2 = v3_dot(ba, ba);
    real h = clamp(v3_dot(pa, ba) / max(length2, (real)1e-30f), 0.0f, 1.0f);
    return v3_length(v3_sub(pa, v3_scale(ba, h))) - radius;
}

// Radii of spheres about the origin holding each finite shape, for the
// scene's bounding sphere (rays that miss it are not marched).
real sphere_bound_radius(real radius) {
    return radius;
}

real box_bound_radius(vec3 size) {
    return 0.5f * v3_length(size);
}

real torus_bound_radius(real major, real minor) {
    return major + minor;
}

real cylinder_bound_radius(real radius, real height) {
    return sqrt(radius * radius + 0.25f * height * height);
}

real capsule_bound_radius(vec3 a, vec3 b, real radius) {
    return max(v3_length(a), v3_length(b)) + radius;
}
