// Stores one value per lane into `channel` of the block's pixels, `block`
// pointing at its top-left pixel in an image of rows of `pitch` pixels of
// CHANNELS floats (lane i is pixel (i % LANES_X, i / LANES_X) of the block).
void store_channel(lane_float v, int channel, __global float *block, int pitch) {
#if LANES == 1
    block[channel] = v;
#else
    float lanes[LANES];
    STORE_LANES(v, 0, lanes);
    for (int i = 0; i < LANES; i++)
        block[((i / LANES_X) * pitch + i % LANES_X) * CHANNELS + channel] = lanes[i];
#endif
}

// Stores a vector per lane into three consecutive channels from `first`.
void store_vec3(vec3 v, int first, __global float *block, int pitch) {
    store_channel(TO_FLOAT(v.x), first, block, pitch);
    store_channel(TO_FLOAT(v.y), first + 1, block, pitch);
    store_channel(TO_FLOAT(v.z), first + 2, block, pitch);
}
