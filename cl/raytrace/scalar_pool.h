/* scalar_pool.h: a scalar model's brick pool packed by post-classification (clwave/raytrace/classified.py `pack`,
 * docs/raytracing.md §10).  Slot s's coefficient i is offset + step q, q the whole number in bits
 * i * bits .. + bits - 1 of the slot's words (least significant first; bits 0..16 per slot, the fewest that keep the
 * pool's one step bound); the slot's words start at `word`.  The pool ends with POOL_PAD spare words, so a row's
 * window never reads past it. */
#ifndef CLW_SCALAR_POOL_H
#define CLW_SCALAR_POOL_H

typedef struct {
    float offset, step; /* the slot's least coefficient, and its step */
    uint word, bits;    /* its first word in the pool, and the bits of each q */
} Quant;

/* q of the slot's coefficients first .. first + n - 1 (n <= 6) into out[n - 1 - r] for r = 0..n-1 (out[0] the
 * last: the order field_bspline.h sums them in): one window of four words holds them all (at most 31 + 6 * 16
 * bits), read as three overlapping 64-bit pairs
 * (a field starting at bit r < 112 lies whole in the pair from word min(r / 32, 2)) */
inline void pool_row(__global const uint *words, const Quant Q, const uint first, const int n, float *out)
{
    const uint at = first * Q.bits, mask = (1u << Q.bits) - 1;
    const uint4 w = vload4(0, words + Q.word + (at >> 5));
    const ulong lo = upsample(w.y, w.x), mid = upsample(w.z, w.y), hi = upsample(w.w, w.z);
#pragma unroll
    for (int k = 0; k < n; k++) {
        const uint r = (at & 31) + k * Q.bits; /* the field's first bit in the window, then in a pair holding it */
        const ulong v = r < 32 ? lo >> r : r < 64 ? mid >> (r - 32) : hi >> (r - 64);
        out[n - 1 - k] = (float)((uint)v & mask);
    }
}

#endif
