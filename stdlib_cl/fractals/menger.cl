// The bounding sphere of the Menger sponge (its distance estimate is the
// IR loop `menger` in fractalc/fractals.py): Syntopia, "Distance Estimated
// 3D Fractals", part III.

//: fractal menger(level: int = 4 0..10)

// All of the sponge lies in the cube, within sqrt(3) of the origin.
real menger_bound_radius(int level) {
    return (real)sqrt(3.0f);
}
