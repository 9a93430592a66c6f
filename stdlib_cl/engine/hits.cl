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
