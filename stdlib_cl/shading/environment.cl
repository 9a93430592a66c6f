// The environment's light in the direct renderer (an `environment` block or
// map; docs/looks.md#environment).

// The environment's irradiance over pi at the unit normal n: what a white
// diffuse surface facing n reflects. ENVIRONMENT_LIGHT holds its 9
// spherical-harmonic coefficients per colour (fractalc/pathtrace.py,
// environment_light; Ramamoorthi and Hanrahan 2001), of the basis 1, y, z,
// x, xy, yz, 3z^2 - 1, xz, x^2 - y^2. The order-2 series can dip below zero
// opposite a bright sun: no light there is negative.
vec3 environment_light(vec3 n) {
    real basis[9] = {(real)1.0f, n.y, n.z, n.x, n.x * n.y, n.y * n.z, 3.0f * n.z * n.z - 1.0f, n.x * n.z,
                     n.x * n.x - n.y * n.y};
    vec3 total = v3((real)0.0f, 0.0f, 0.0f);
    for (int k = 0; k < 9; k++)
        total = v3_add(total, v3_scale(v3(ENVIRONMENT_LIGHT[3 * k], ENVIRONMENT_LIGHT[3 * k + 1],
                                          ENVIRONMENT_LIGHT[3 * k + 2]), basis[k]));
    return v3(max(total.x, 0.0f), max(total.y, 0.0f), max(total.z, 0.0f));
}
