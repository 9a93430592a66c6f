// A per-lane hash (PCG), for stratified jitter that is the same on every run.
lane_uint hash_lanes(lane_uint v) {
    lane_uint state = v * 747796405u + 2891336453u;
    lane_uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

real unit_random(lane_uint v) {
    return TO_REAL(hash_lanes(v) >> 8) * (1.0f / 16777216.0f);
}
