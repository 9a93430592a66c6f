// Orbit traps (Syntopia, "Distance Estimated 3D Fractals" part II): the
// smallest distance of a fractal's orbit to the origin and to each
// coordinate plane, for colouring. Kinds: 0 the origin; 1, 2, 3 the planes
// x = 0, y = 0, z = 0; 4 the nearest of the three planes.

typedef struct { real origin, x, y, z; } orbit_trap;

orbit_trap orbit_trap_start(void) {
    orbit_trap trap = { (real)1e30f, (real)1e30f, (real)1e30f, (real)1e30f };
    return trap;
}

// Adds orbit point z for the lanes still iterating. A DE alone passes no
// trap (0): inlined with a constant 0, the updates vanish from its loop.
void orbit_trap_add(orbit_trap *trap, vec3 z, mask active) {
    if (trap == 0)
        return;
    trap->origin = SELECT(trap->origin, min(trap->origin, v3_length(z)), active);
    trap->x = SELECT(trap->x, min(trap->x, fabs(z.x)), active);
    trap->y = SELECT(trap->y, min(trap->y, fabs(z.y)), active);
    trap->z = SELECT(trap->z, min(trap->z, fabs(z.z)), active);
}

real orbit_trap_value(orbit_trap trap, int kind) {
    switch (kind) {
        case 0: return trap.origin;
        case 1: return trap.x;
        case 2: return trap.y;
        case 3: return trap.z;
        default: return min(trap.x, min(trap.y, trap.z));
    }
}
