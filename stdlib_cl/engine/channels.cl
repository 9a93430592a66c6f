// A work-item's pixels, lane i being pixel (i % LANES_X, i / LANES_X) of
// its block, gathered channel by channel in private memory, a lane's value
// by its own store, and written to the image a row of the block at a time
// (a row's pixels are adjacent there): storing each channel straight to
// the image, lane by lane in a loop, became scattered stores (PoCL's
// vscatterdps, slow on AMD's cores; bulb-640 6% faster on PoCL, 1.5% on
// Intel's runtime; a loop into private memory scattered there too).
typedef struct { float values[LANES * CHANNELS]; } block_pixels;

// Sets `channel` of every pixel of the block to its lane's value.
void store_channel(lane_float v, int channel, block_pixels *pixels) {
#if LANES == 1
    pixels->values[channel] = v;
#else
    float *at = pixels->values + channel;
    at[0] = v.s0; at[CHANNELS] = v.s1;
#if LANES > 2
    at[2 * CHANNELS] = v.s2; at[3 * CHANNELS] = v.s3;
#endif
#if LANES > 4
    at[4 * CHANNELS] = v.s4; at[5 * CHANNELS] = v.s5; at[6 * CHANNELS] = v.s6; at[7 * CHANNELS] = v.s7;
#endif
#if LANES > 8
    at[8 * CHANNELS] = v.s8; at[9 * CHANNELS] = v.s9; at[10 * CHANNELS] = v.sa; at[11 * CHANNELS] = v.sb;
    at[12 * CHANNELS] = v.sc; at[13 * CHANNELS] = v.sd; at[14 * CHANNELS] = v.se; at[15 * CHANNELS] = v.sf;
#endif
#endif
}

// Sets three consecutive channels from `first` to a vector per lane.
void store_vec3(vec3 v, int first, block_pixels *pixels) {
    store_channel(TO_FLOAT(v.x), first, pixels);
    store_channel(TO_FLOAT(v.y), first + 1, pixels);
    store_channel(TO_FLOAT(v.z), first + 2, pixels);
}

// Writes the block's pixels to the image, `block` pointing at its top-left
// pixel in rows of `pitch` pixels of CHANNELS floats.
void write_block(block_pixels *pixels, __global float *block, int pitch) {
    for (int row = 0; row < LANES_Y; row++)
        for (int k = 0; k < LANES_X * CHANNELS; k++)
            block[row * pitch * CHANNELS + k] = pixels->values[row * LANES_X * CHANNELS + k];
}
