/* splat_raster.cl: accumulate the splats of each image tile (paper §4.1, eq. 29).
 *
 * Footprint textures are sampled at exactly 1/P pixel (P integer), so along an image row the
 * bilinear weights are the same for every pixel and pixel x reads texel ib + P x.  Each texture
 * is stored as P phase planes (plane p holds texels p, p + P, p + 2P, ... of every row), so a row
 * of pixels reads four contiguous runs of memory: the loop over x vectorises.  Along an axis
 * where a footprint is piecewise constant (Haar along a world axis) the texels are instead its
 * cells, looked up by nearest sample at any step (lookup bits of tex_int): cells along v pick
 * one texel row (weight 0 on the next), cells along u give each pixel its nearest column.
 *
 * splat_accumulate
 *   ranges   in  (tiles,) uint2: [start, end) into vals
 *   vals     in  (total,) uint: splat indices, sorted by tile, importance order within a tile
 *   first    index of the chunk's first coefficient (values are indexed first + splat)
 *   centre, bbox, stex in: from splat_project
 *   values   in  (K,) float4: coefficient per channel (c; the 2^{-m/2} is in the texture)
 *   tex_int  in  (T,) int4: (offset, columns per plane, rows per plane, lookup); planes carry
 *                a margin of zero texels: one column on either side, one row above and two
 *                below (a nearest row that rounds onto the bottom margin still reads its
 *                zero-weighted next row inside the plane).  lookup bit 0 (u) and bit 1 (v): set,
 *                the texels along that axis are samples at 1/P pixel, interpolated linearly
 *                (along u read from P phase planes, so the weights are the same for every pixel
 *                of a row); clear, they are cells at any texel step, looked up by nearest
 *                sample (along u gathered per pixel from one plane; clwave.footprint "cells"):
 *                exact for Haar footprints along a world axis, whose jumps lie on the cell
 *                edges, where linear interpolation would smear each jump over a texel
 *   tex_map  in  (T,) float4: (centre_u, centre_v) in texels of the unpadded texture, and the
 *                texel steps per pixel (s_u, s_v); s_u = P for phase planes
 *   texels   in  phase planes, (P, rows, columns) per texture; 16 zeros before the first
 *                and 32 after the last, so whole 16-pixel rows may be read
 *   fb       in/out (H * W,) float4: the sum is added, so chunks accumulate
 * Build: -DCLW_CHANNELS=C (1..4) accumulates channels 0..C-1 only (the others of fb keep
 *   their values).
 * Grid: one work-group per tile, local size CLW_TILE * CLW_TILE / CLW_PX; work-item l
 *   owns CLW_PX consecutive pixels of row l / (CLW_TILE / CLW_PX).  CLW_PX = CLW_TILE
 *   (a whole row per item) suits PoCL; CLW_PX = 1 (one pixel per item) suits GPUs.
 * Assumes: each pixel is owned by one work-item and splats are visited in sorted order,
 *   so the image is bit-identical from run to run. */
#include "clw_common.h"

#ifndef CLW_PX
#define CLW_PX CLW_TILE
#endif
#ifndef CLW_BATCH
#define CLW_BATCH 64
#endif
#ifndef CLW_CHANNELS
#define CLW_CHANNELS 4
#endif
#define CLW_ITEMS_PER_ROW (CLW_TILE / CLW_PX)

__kernel void splat_accumulate(const int width, const int height, const int tiles_x,
                               __global const uint2 *ranges, __global const uint *vals, const uint first,
                               __global const float2 *centre, __global const int4 *bbox,
                               __global const int *stex, __global const float4 *values,
                               __global const int4 *tex_int, __global const float4 *tex_map,
                               __global const float *texels, __global float4 *fb)
{
    /* per splat of the batch, everything that does not depend on the row: its pixel box, the
     * lookup bits in a.w and the row stride a.z; u from phase planes: the texel offsets of pixel
     * 0 in the two phase planes (a.x, a.y; row 0 of the padded plane) and the column weight f.x;
     * u cells: a.x the start of row 0, a.y the column count (columns -1 and a.y are the zero
     * margin), f.x = centre_u + 1/2 and l_cell = (centre column, s_u).  f.y, f.z, f.w = centre
     * row, texture centre row (+ 1/2 for v cells: floor gives the nearest texel), s_v, from
     * which each row finds its texel row */
    __local int4 l_box[CLW_BATCH];
    __local int4 l_addr[CLW_BATCH];
    __local float4 l_f[CLW_BATCH];
    __local float4 l_w[CLW_BATCH];
    __local float2 l_cell[CLW_BATCH];

    const int tile = get_group_id(0);
    const int lid = get_local_id(0);
    const int nitems = get_local_size(0);
    const int y = (tile / tiles_x) * CLW_TILE + lid / CLW_ITEMS_PER_ROW;
    const int xbase = (tile % tiles_x) * CLW_TILE + (lid % CLW_ITEMS_PER_ROW) * CLW_PX;
#if CLW_PX == 16
    /* a row of 16 pixels as float16 vectors, one per channel (PoCL vectorises these) */
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    float16 acc0 = 0.0f;
#if CLW_CHANNELS > 1
    float16 acc1 = 0.0f;
#endif
#if CLW_CHANNELS > 2
    float16 acc2 = 0.0f;
#endif
#if CLW_CHANNELS > 3
    float16 acc3 = 0.0f;
#endif
#else
    float4 acc[CLW_PX];
    for (int p = 0; p < CLW_PX; ++p)
        acc[p] = (float4)(0.0f);
#endif

    const uint2 r = ranges[tile];
    for (uint b0 = r.x; b0 < r.y; b0 += CLW_BATCH) {
        const uint nb = min((uint)CLW_BATCH, r.y - b0);
        for (uint k = lid; k < nb; k += nitems) {
            const uint s = vals[b0 + k];
            const int4 t = tex_int[stex[s]];
            const float4 m = tex_map[stex[s]];
            const float2 c = centre[s];
            float fx;
            if (t.w & 1) {
                const int P = (int)m.z;
                const float base = m.x - c.x * m.z;  /* texel of pixel x: base + P x */
                const float fib = floor(base);
                const int ib = (int)fib;
                const int p0 = ((ib % P) + P) % P;       /* phase plane and column of texel ib */
                const int q0 = (ib - p0) / P;
                const int p1 = (p0 + 1 == P) ? 0 : p0 + 1;
                const int q1 = (p0 + 1 == P) ? q0 + 1 : q0;
                /* +1: the zero margin of the columns; the row margin is added per row */
                l_addr[k] = (int4)(t.x + p0 * t.z * t.y + q0 + 1, t.x + p1 * t.z * t.y + q1 + 1, t.y, t.w);
                fx = base - fib;
            } else {  /* +1/2: floor gives the nearest texel */
                l_addr[k] = (int4)(t.x + 1, t.y - 2, t.y, t.w);
                fx = m.x + 0.5f;
            }
            l_f[k] = (float4)(fx, c.y, (t.w & 2) ? m.y : m.y + 0.5f, m.w);
            l_cell[k] = (float2)(c.x, m.z);
            l_box[k] = bbox[s];
            l_w[k] = values[first + s];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (uint k = 0; k < nb; ++k) {
            const int4 bx = l_box[k];
            const int x0 = max(bx.x, xbase), x1 = min(bx.z, xbase + CLW_PX - 1);
            if (y < bx.y || y > bx.w || x0 > x1)
                continue;
            const int4 a = l_addr[k];
            const float4 f = l_f[k];
            const float4 w = l_w[k];
            const float tv = f.z + (f.y - (float)y) * f.w;  /* image rows go down, v goes up */
            const float fiv = floor(tv);
            const int row = ((int)fiv + 1) * a.z;          /* +1: the zero margin; rows iv, iv + 1 */
            __global const float *r00 = texels + a.x + row;
            __global const float *r01 = texels + a.y + row;
            const float fu = f.x, fv = (a.w & 2) ? tv - fiv : 0.0f;
            const float w00 = (1.0f - fu) * (1.0f - fv), w01 = fu * (1.0f - fv);
            const float w10 = (1.0f - fu) * fv, w11 = fu * fv;
            const float2 cs = l_cell[k];
#if CLW_PX == 16
            float16 sample;
            if (a.w & 1) {
                /* all 16 lanes read (the pool has 16 zeros before and 32 after it), masked lanes drop */
                sample = w00 * vload16(0, r00 + xbase) + w01 * vload16(0, r01 + xbase)
                       + w10 * vload16(0, r00 + xbase + a.z) + w11 * vload16(0, r01 + xbase + a.z);
            } else {  /* u cells: each lane takes its nearest column (a.y of them, a handful: 2 for
                       * footprints), by selects rather than gathers; lanes off the texture keep 0 */
                const int16 col = convert_int16(floor(f.x + (((float16)((float)xbase) + lane) - cs.x) * cs.y));
                sample = 0.0f;
                for (int q = 0; q < a.y; ++q) {
                    const float cell = (a.w & 2) ? (1.0f - fv) * r00[q] + fv * r00[q + a.z] : r00[q];
                    sample = select(sample, (float16)(cell), col == (int16)(q));
                }
            }
            const float16 masked = select((float16)(0.0f), sample,
                                          isgreaterequal(lane, (float16)(x0 - xbase)) &
                                          islessequal(lane, (float16)(x1 - xbase)));
            acc0 += w.x * masked;
#if CLW_CHANNELS > 1
            acc1 += w.y * masked;
#endif
#if CLW_CHANNELS > 2
            acc2 += w.z * masked;
#endif
#if CLW_CHANNELS > 3
            acc3 += w.w * masked;
#endif
#else
            for (int x = x0; x <= x1; ++x) {
                float sample;
                if (a.w & 1) {
                    sample = w00 * r00[x] + w01 * r01[x] + w10 * r00[x + a.z] + w11 * r01[x + a.z];
                } else {
                    const int col = clamp((int)floor(f.x + ((float)x - cs.x) * cs.y), -1, a.y);
                    sample = r00[col];
                    if (a.w & 2)
                        sample = (1.0f - fv) * sample + fv * r00[col + a.z];
                }
                acc[x - xbase] += w * sample;
            }
#endif
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (y >= height)
        return;
#if CLW_PX == 16
    float a0[16], a1[16] = {0}, a2[16] = {0}, a3[16] = {0};
    vstore16(acc0, 0, a0);
#if CLW_CHANNELS > 1
    vstore16(acc1, 0, a1);
#endif
#if CLW_CHANNELS > 2
    vstore16(acc2, 0, a2);
#endif
#if CLW_CHANNELS > 3
    vstore16(acc3, 0, a3);
#endif
    for (int p = 0; p < 16; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += (float4)(a0[p], a1[p], a2[p], a3[p]);
#else
    for (int p = 0; p < CLW_PX; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += acc[p];
#endif
}
