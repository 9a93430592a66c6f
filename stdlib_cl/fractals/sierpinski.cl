// The level-N solid Sierpinski tetrahedron (LANGUAGE.md, "Fractals"): the
// tetrahedron T with vertices a1 = (1,1,1), a2 = (-1,-1,1), a3 = (1,-1,-1),
// a4 = (-1,1,-1) at level 0; level N is the union of the four level-(N-1)
// solids scaled by 1/2 about each vertex. Syntopia, "Distance Estimated 3D
// Fractals", part III (the folding recursive tetrahedron).
//
// The estimate is the exact distance. The reflection swapping a1 and ai
// (in the plane x+y=0, y+z=0 or x+z=0) maps the solid to itself, and the
// copy scaled about a1 lies on a1's side of each of those planes; so the
// three folds that bring p to a1's side keep its distance to the solid,
// and the copy about a1 is then the nearest: dist(p) = dist(2p - a1) / 2,
// down to the distance to T itself (the scale 2^-N divided out).

// Folds p by the three reflections swapping a1 with a2, a4, a3, each when
// a1 . p is below (side 1) or above (side -1) the other vertex's dot
// product. A reflection leaves the dot products of the two vertices it does
// not swap as they were, so afterwards a1 . p is the largest (smallest).
vec3 sierpinski_fold(vec3 p, scalar side) {
    mask m = side * (p.x + p.y) < 0.0f;
    p = v3(SELECT(p.x, -p.y, m), SELECT(p.y, -p.x, m), p.z);
    m = side * (p.x + p.z) < 0.0f;
    p = v3(SELECT(p.x, -p.z, m), p.y, SELECT(p.z, -p.x, m));
    m = side * (p.y + p.z) < 0.0f;
    return v3(p.x, SELECT(p.y, -p.z, m), SELECT(p.z, -p.y, m));
}

// Exact signed distance to T. Folded so that the face a2 a3 a4
// (x + y + z = -1) is the one whose plane is farthest out, the point is
// inside T if it is inside that plane, and otherwise nearest to that face.
// Sorting x >= y >= z (reflections mapping the face to itself) makes a3 its
// nearest vertex: the point is then nearest to the face's inside, or, past
// the edge a3 a4 (in-plane distance (x + y - 2z - 2) / sqrt(6) > 0), to
// that edge, the points (t, -t, -1) for t in [-1, 1].
real sierpinski_tetrahedron(vec3 p) {
    p = sierpinski_fold(p, -1.0f);
    real plane = (-(p.x + p.y + p.z) - 1.0f) * (1.0f / sqrt(3.0f));
    real x = max(p.x, max(p.y, p.z)), z = min(p.x, min(p.y, p.z));
    real y = max(min(p.x, p.y), min(max(p.x, p.y), p.z));
    real t = min(0.5f * (x - y), 1.0f);
    real edge = sqrt((x - t) * (x - t) + (y + t) * (y + t) + (z + 1.0f) * (z + 1.0f));
    real outside = SELECT(plane, edge, x + y - 2.0f * z - 2.0f > 0.0f);
    return SELECT(outside, plane, plane <= 0.0f);
}

// The iteration, recording its orbit in `trap`.
real sierpinski_orbit(vec3 p, int level, orbit_trap *trap) {
    // Clamping p to a box holding the solid only brings it closer to the
    // solid (so the estimate stays a lower bound) and keeps 2^level |p|
    // squared finite.
    p = v3(clamp(p.x, -1e15f, 1e15f), clamp(p.y, -1e15f, 1e15f), clamp(p.z, -1e15f, 1e15f));
    real size = 1.0f;
    for (int i = 0; i < level; i++) {
        p = sierpinski_fold(p, 1.0f);
        p = v3(2.0f * p.x - 1.0f, 2.0f * p.y - 1.0f, 2.0f * p.z - 1.0f);
        orbit_trap_add(trap, p, MASK_TRUE);
        size = size * 0.5f;
    }
    return sierpinski_tetrahedron(p) * size;
}

//: fractal sierpinski(level: int = 6 0..10)
real de_sierpinski(vec3 p, int level) {
    return sierpinski_orbit(p, level, 0);
}

// The orbit trap of the same iteration, for `.color(orbit_trap(...))`.
real sierpinski_orbit_trap(vec3 p, int level, int kind) {
    orbit_trap trap = orbit_trap_start();
    sierpinski_orbit(p, level, &trap);
    return orbit_trap_value(trap, kind);
}

// All of T, so all of the solid, lies within |ai| = sqrt(3) of the origin.
real sierpinski_bound_radius(int level) {
    return (real)sqrt(3.0f);
}
