// The bounding sphere of the solid Sierpinski tetrahedron (its distance
// estimate is the IR loop `sierpinski` in fractalc/fractals.py): Syntopia,
// "Distance Estimated 3D Fractals", part III.

//: fractal sierpinski(level: int = 6 0..10)

// All of T, so all of the solid, lies within |ai| = sqrt(3) of the origin.
real sierpinski_bound_radius(int level) {
    return (real)sqrt(3.0f);
}
