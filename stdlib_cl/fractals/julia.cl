// The bounding sphere of quaternion Julia sets (their distance estimate is
// the IR loop `julia` in fractalc/fractals.py): Hart, Sandin and Kauffman
// 1989; Syntopia, "Distance Estimated 3D Fractals", part IV.

//: fractal julia(c: vec4 = (-0.2, 0.6, 0.2, 0), slice: num = 0, iterations: int = 12 1..1000, bailout: num = 4 >0)

// A sphere holding every point where the DE can be <= 0. With
// R = (1 + sqrt(1 + 4|c|)) / 2, the root of R^2 - R = |c| (so R >= 1): if
// |q| > R then |q^2 + c| >= |q|^2 - |c| > |q|, so |q| grows, never reaches
// 0 (dr > 0) and ends above 1: DE > 0. |q|^2 = |p|^2 + slice^2, so that
// holds for |p| > sqrt(R^2 - slice^2). If |slice| >= R the slice is empty:
// the radius is then -1, and the sphere distance |p| + 1 (a lower bound on
// the distance to nothing) never reaches a hit.
real julia_bound_radius(real cx, real cy, real cz, real cw, real slice, int iterations, real bailout) {
    real c = sqrt(cx * cx + cy * cy + cz * cz + cw * cw);
    real radius = 0.5f * (1.0f + sqrt(1.0f + 4.0f * c));
    real squared = radius * radius - slice * slice;
    return SELECT((real)-1.0f, sqrt(max(squared, 0.0f)), squared > 0.0f);
}
