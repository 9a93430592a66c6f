// Domain warps and the factor that keeps their step safe. A warp q(p) with
// Jacobian J scales gradients by at most the largest singular value of J;
// both warps here are a rotation plus a shear of length g, whose largest
// singular value is (g + sqrt(g^2 + 4)) / 2. Dividing the warped distance by
// it keeps the estimate below the true distance (locally), after Quilez's
// "opTwist"/"opCheapBend".
real shear_lipschitz(real g) {
    return 0.5f * (g + sqrt(g * g + 4.0f));
}

// Twist about z: the point is rotated about z by -rate * z.
vec3 twist_point(vec3 p, real rate) {
    real angle = rate * p.z;
    real c = cos(angle), s = sin(angle);
    return v3(c * p.x + s * p.y, c * p.y - s * p.x, p.z);
}

real twist_lipschitz(vec3 p, real rate) {
    return shear_lipschitz(fabs(rate) * sqrt(p.x * p.x + p.y * p.y));
}

// Bend in the xz plane: (x, z) is rotated by rate * x.
vec3 bend_point(vec3 p, real rate) {
    real angle = rate * p.x;
    real c = cos(angle), s = sin(angle);
    return v3(c * p.x - s * p.z, p.y, s * p.x + c * p.z);
}

real bend_lipschitz(vec3 p, real rate) {
    return shear_lipschitz(fabs(rate) * sqrt(p.x * p.x + p.z * p.z));
}
