/* scalar_pool.h: a scalar model's brick pool packed by post-classification (clwave/raytrace/classified.py `pack`,
 * docs/raytracing.md §10).  Slot s's coefficient i is offset + step q, q the whole number in bits
 * i * bits .. + bits - 1 of the slot's words (least significant first; bits 0..14 or 16 per slot, the fewest that
 * keep the pool's one step bound); the slot's words start at `word`.  The pool ends with POOL_PAD spare words, so a
 * row's eight bytes never lie past it. */
#ifndef CLW_SCALAR_POOL_H
#define CLW_SCALAR_POOL_H

typedef struct {
    float offset, step; /* the slot's least coefficient, and its step */
    uint word, bits;    /* its first word in the pool, and the bits of each q */
} Quant;

/* q of the slot's coefficients first .. first + n - 1 (n <= 6) into out[n - 1 - r] for r = 0..n-1 (out[0] the
 * last: the order field_bspline.h sums them in), four at a time: four fields of b bits from bit a lie in the eight
 * bytes from byte a / 8 (a % 8 + 4 b <= 64: b <= 14, or b = 16 and a % 8 = 0), one unaligned load and a vector shift
 * (the bytes as a little-endian ulong, as on every OpenCL device we know) */
inline void pool_row(__global const uchar *pool, const Quant Q, const uint first, const int n, float *out)
{
    const uint mask = (1u << Q.bits) - 1;
    const ulong4 fields = (ulong4)(0, 1, 2, 3) * Q.bits;
    __global const uchar *slot = pool + ((size_t)Q.word << 2);
#pragma unroll
    for (int k = 0; k < n; k += 4) {
        const uint a = (first + k) * Q.bits;
        const ulong x = as_ulong(vload8(0, slot + (a >> 3))) >> (a & 7);
        const float4 v = convert_float4(convert_uint4((ulong4)(x) >> fields) & mask);
        const float q[4] = {v.x, v.y, v.z, v.w};
#pragma unroll
        for (int r = k; r < min(k + 4, n); r++)
            out[n - 1 - r] = q[r - k];
    }
}

#endif
