// Surface normals and Blinn-Phong lighting. Normals are the normalised
// gradient of the distance by finite differences with a step h tied to the
// hit threshold, so that detail below the pixel footprint is not amplified:
// tetrahedral (4 evaluations, Quilez "normals for an SDF"), central (6), or
// forward (3: the march's last evaluation, at the hit, is the fourth).
// Their estimates are taken two at a time, side by side
// (`distance_estimates`).
vec3 tetrahedral_normal(vec3 p, real h, PARAMS_SPACE scalar *params) {
    COUNT_EVALUATIONS(COUNT_NORMALS, scoped(params), 4.0f);
    real a, b, c, d;
    distance_estimates(v3(p.x + h, p.y - h, p.z - h), v3(p.x - h, p.y - h, p.z + h), &a, &b, params);
    distance_estimates(v3(p.x - h, p.y + h, p.z - h), v3(p.x + h, p.y + h, p.z + h), &c, &d, params);
    // differences first: a sum of two estimates near float's largest (a
    // point deep inside a far plane) would overflow
    return v3_normalize(v3((a - b) + (d - c), (c - a) + (d - b), (b - a) + (d - c)));
}

// Forward differences from `p`, whose estimate `here` the march already
// took: one evaluation fewer than the tetrahedron, with a first-order error
// (h times the surface's curvature; h is one hit threshold).
vec3 forward_normal(vec3 p, real here, real h, PARAMS_SPACE scalar *params) {
    COUNT_EVALUATIONS(COUNT_NORMALS, scoped(params), 3.0f);
    real x, y;
    distance_estimates(v3(p.x + h, p.y, p.z), v3(p.x, p.y + h, p.z), &x, &y, params);
    real z = distance_estimate(v3(p.x, p.y, p.z + h), params);
    return v3_normalize(v3(x - here, y - here, z - here));
}

vec3 central_normal(vec3 p, real h, PARAMS_SPACE scalar *params) {
    COUNT_EVALUATIONS(COUNT_NORMALS, scoped(params), 6.0f);
    real x0, x1, y0, y1, z0, z1;
    distance_estimates(v3(p.x + h, p.y, p.z), v3(p.x - h, p.y, p.z), &x0, &x1, params);
    distance_estimates(v3(p.x, p.y + h, p.z), v3(p.x, p.y - h, p.z), &y0, &y1, params);
    distance_estimates(v3(p.x, p.y, p.z + h), v3(p.x, p.y, p.z - h), &z0, &z1, params);
    return v3_normalize(v3(x0 - x1, y0 - y1, z0 - z1));
}

// Blinn-Phong: (albedo * max(n.l, 0) + specular * max(n.h, 0)^shininess)
// times the light's radiance (colour * intensity * visibility). The power
// as exp2(s log2 x), x > 0: PoCL's pow costs about ten times as much.
vec3 blinn_phong(vec3 normal, vec3 to_light, vec3 to_eye, vec3 albedo,
                 real specular, real shininess, vec3 radiance) {
    real diffuse = max(v3_dot(normal, to_light), 0.0f);
    vec3 halfway = v3_normalize(v3_add(to_light, to_eye));
    real highlight = specular * exp2(shininess * log2(max(v3_dot(normal, halfway), 1e-6f)));
    highlight = SELECT((real)0.0f, highlight, diffuse > 0.0f);
    return v3_mul(v3_add(v3_scale(albedo, diffuse), v3(highlight, highlight, highlight)), radiance);
}
