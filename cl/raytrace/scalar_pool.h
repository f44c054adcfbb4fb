/* scalar_pool.h: a scalar model's brick pool packed by post-classification (clwave/raytrace/classified.py `pack`,
 * docs/raytracing.md §10).  Slot s's coefficient (x, y, z) is offset + step q, q = base + the whole number in bits
 * i * bits .. + bits - 1 of its tile's words (least significant first), for the tile (TILE x TILE of the slot's x rows
 * in y and z) holding it and i its place there (rows in z, y order, then x).  The slot's words start at `word` with an
 * entry a tile (z, y order): its first word in the pool, and base | bits << 16 (bits 0..14 or 16, the fewest that keep
 * the slot's step).  The pool ends with POOL_PAD spare words, so a row's eight bytes never lie past it. */
#ifndef CLW_SCALAR_POOL_H
#define CLW_SCALAR_POOL_H

#define POOL_TILE 4 /* classified.py's TILE */

typedef struct {
    float offset, step; /* the slot's least coefficient, and its step (one for the full-detail slots, one for
                         * the coarser details': classified.py `pack`) */
    uint word, tiles_y; /* its first word in the pool (its tiles' entries), and its tiles along y */
} Quant;

/* q of coefficients (x .. x + n - 1, y, z) (n <= 6) of a slot (`box`: nx, ny, nz) into out[n - 1 - r] for r = 0..n-1
 * (out[0] the last: the order field_bspline.h sums them in), four at a time from the row's tile: four fields of b bits
 * from bit a lie in the eight bytes from byte a / 8 (a % 8 + 4 b <= 64: b <= 14, or b = 16 and a % 8 = 0, the tile's
 * words starting whole), one unaligned load and a vector shift (the bytes as a little-endian ulong, as on every
 * OpenCL device we know) */
inline void pool_row(__global const uchar *pool, const Quant Q, const int4 box, const int x, const int y, const int z,
                     const int n, float *out)
{
    const int ty = y / POOL_TILE, tz = z / POOL_TILE, y0 = ty * POOL_TILE;
    const uint2 tile = vload2(tz * Q.tiles_y + ty, (__global const uint *)pool + Q.word);
    const uint bits = tile.y >> 16, mask = (1u << bits) - 1;
    const float base = tile.y & 0xFFFF;
    const uint first = ((z - tz * POOL_TILE) * min(POOL_TILE, box.y - y0) + y - y0) * box.x + x;
    const ulong4 fields = (ulong4)(0, 1, 2, 3) * bits;
    __global const uchar *words = pool + ((size_t)tile.x << 2);
#pragma unroll
    for (int k = 0; k < n; k += 4) {
        const uint a = (first + k) * bits;
        const ulong w = as_ulong(vload8(0, words + (a >> 3))) >> (a & 7);
        const float4 v = base + convert_float4(convert_uint4((ulong4)(w) >> fields) & mask);
        const float q[4] = {v.x, v.y, v.z, v.w};
#pragma unroll
        for (int r = k; r < min(k + 4, n); r++)
            out[n - 1 - r] = q[r - k];
    }
}

/* q of the j^3 coefficients of a cell of a slot (nx, ny: its box's rows and columns) ending at its coefficient
 * last.xyz into q (x fastest, then y, z: CORNER_COEF's order), each row from its own tile (a cell's rows come from up to
 * 2 x 2 tiles, 3 x 3 at order 6) */
__attribute__((always_inline)) inline void pool_cell(__global const uchar *pool, const Quant Q, const int nx,
                                                     const int ny, const int4 last, const int j, real *q)
{
    const int4 box = (int4)(nx, ny, 0, 0);
#pragma unroll
    for (int rz = 0; rz < j; rz++)
#pragma unroll
        for (int ry = 0; ry < j; ry++) {
            float row[MAX_ORDER];
            pool_row(pool, Q, box, last.x - (j - 1), last.y - ry, last.z - rz, j, row);
#pragma unroll
            for (int rx = 0; rx < j; rx++)
                q[(rz * j + ry) * j + rx] = row[rx];
        }
}

#endif
