// The bounding sphere of the Mandelbulb (its distance estimate is the IR
// loop `mandelbulb` in fractalc/fractals.py): Syntopia, "Distance
// Estimated 3D Fractals", parts IV and V.

//: fractal mandelbulb(power: num = 8 1..32, iterations: int = 12 1..1000, bailout: num = 2 >0)

// A sphere holding every point where the DE can be <= 0, i.e. where the
// final |z| can be <= 1. Let R = |p| with R^(power-1) >= 2 (so R > 1). If
// |z| >= R then |z^power + p| >= |z|^power - R >= 2|z| - R >= |z|: |z| never
// falls below R > 1, so the DE is > 0 for |p| >= 2^(1/(power-1)). Power 1 is
// z -> z + p, z_n = (n+1) p, and |p| > 1 suffices. Near power 1 the radius
// grows without bound (+inf in float: no bound).
real mandelbulb_bound_radius(real power, int iterations, real bailout) {
    return SELECT(pow((real)2.0f, 1.0f / (power - 1.0f)), (real)1.0f, power <= 1.0f);
}
