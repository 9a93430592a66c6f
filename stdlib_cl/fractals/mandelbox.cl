// The bounding sphere of Tom Lowe's Mandelbox (its distance estimate is
// the IR loop `mandelbox` in fractalc/fractals.py): Syntopia, "Distance
// Estimated 3D Fractals", part VI.

//: fractal mandelbox(scale: num = 2, min_radius: num = 0.5 >0 <=fixed_radius, fixed_radius: num = 1 >0, fold_limit: num = 1 >0, iterations: int = 12 1..1000)

// A sphere holding the set (the points whose orbits do not escape), with
// z != 0 outside, so the DE is > 0 there. Let L = fold_limit, s = scale and
// P = |p_i| the largest coordinate of p, p_i > 0 say, and x_n the i-th
// coordinate of z_n. The box fold maps x > 2L to 2L - x, x < -2L to
// -2L - x, and the sphere fold multiplies by a factor >= 1.
// - s > 1 and P > B = 2L (s + 1) / (s - 1): from x >= P, the next
//   coordinate is <= P - s (x - 2L) <= -2L, and the one after it is
//   >= P + s (s (x - 2L) - P - 2L) >= x: the orbit alternates in sign and
//   grows, and never reaches 0. Outside the cube [-B, B]^3, so outside the
//   sphere of radius sqrt(3) B.
// - s <= 0 and P > 2L: from x >= P > 2L the next coordinate is
//   P + |s| fold (x - 2L) >= P: radius sqrt(3) 2L.
// - 0 < s <= 1: no bound is proven (+inf).
real mandelbox_bound_radius(real scale, real min_radius, real fixed_radius, real fold_limit, int iterations) {
    real cube = SELECT(2.0f * fold_limit * (scale + 1.0f) / (scale - 1.0f), 2.0f * fold_limit, scale <= 0.0f);
    return SELECT((real)INFINITY, sqrt(3.0f) * cube, (scale <= 0.0f) | (scale > 1.0f));
}
