/* splat_raster.cl: accumulate the splats of each image tile (paper §4.1, eq. 29).
 *
 * Footprint textures are sampled at exactly 1/P pixel (P integer), so along an image row the
 * bilinear weights are the same for every pixel and pixel x reads texel ib + P x.  Each texture
 * is stored as P phase planes (plane p holds texels p, p + P, p + 2P, ... of every row), so a row
 * of pixels reads four contiguous runs of memory: the loop over x vectorises.
 *
 * splat_accumulate
 *   ranges   in  (tiles,) uint2: [start, end) into vals
 *   vals     in  (total,) uint: splat indices, sorted by tile, importance order within a tile
 *   first    index of the chunk's first coefficient (values are indexed first + splat)
 *   centre, bbox, stex in: from splat_project
 *   values   in  (K,) float4: coefficient per channel (c; the 2^{-m/2} is in the texture)
 *   tex_int  in  (T,) int4: (offset, columns per plane, rows per plane, P); planes carry a
 *                margin of one zero texel on every side
 *   tex_map  in  (T,) float4: (centre_u, centre_v) in texels of the unpadded texture, unused, unused
 *   texels   in  phase planes, (P, rows, columns) per texture; 16 zeros before the first
 *                and 32 after the last, so whole 16-pixel rows may be read
 *   fb       in/out (H * W,) float4: the sum is added, so chunks accumulate
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
#define CLW_ITEMS_PER_ROW (CLW_TILE / CLW_PX)

__kernel void splat_accumulate(const int width, const int height, const int tiles_x,
                               __global const uint2 *ranges, __global const uint *vals, const uint first,
                               __global const float2 *centre, __global const int4 *bbox,
                               __global const int *stex, __global const float4 *values,
                               __global const int4 *tex_int, __global const float4 *tex_map,
                               __global const float *texels, __global float4 *fb)
{
    __local float2 l_centre[CLW_BATCH];
    __local int4 l_box[CLW_BATCH];
    __local int l_tex[CLW_BATCH];
    __local float4 l_w[CLW_BATCH];

    const int tile = get_group_id(0);
    const int lid = get_local_id(0);
    const int nitems = get_local_size(0);
    const int y = (tile / tiles_x) * CLW_TILE + lid / CLW_ITEMS_PER_ROW;
    const int xbase = (tile % tiles_x) * CLW_TILE + (lid % CLW_ITEMS_PER_ROW) * CLW_PX;
#if CLW_PX == 16
    /* a row of 16 pixels as float16 vectors, one per channel (PoCL vectorises these) */
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    float16 acc0 = 0.0f, acc1 = 0.0f, acc2 = 0.0f, acc3 = 0.0f;
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
            l_centre[k] = centre[s];
            l_box[k] = bbox[s];
            l_tex[k] = stex[s];
            l_w[k] = values[first + s];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (uint k = 0; k < nb; ++k) {
            const int4 bx = l_box[k];
            const int x0 = max(bx.x, xbase), x1 = min(bx.z, xbase + CLW_PX - 1);
            if (y < bx.y || y > bx.w || x0 > x1)
                continue;
            const int4 t = tex_int[l_tex[k]];
            const float2 m = tex_map[l_tex[k]].xy;
            const float2 c = l_centre[k];
            const int P = t.w;
            const float tv = m.y + (c.y - (float)y) * (float)P;  /* image rows go down, v goes up */
            const float base = m.x - c.x * (float)P;             /* texel of pixel x: base + P x */
            const float fiv = floor(tv), fib = floor(base);
            const float fv = tv - fiv, fu = base - fib;
            const int iv = (int)fiv, ib = (int)fib;
            const int p0 = ((ib % P) + P) % P;
            const int q0 = (ib - p0) / P;
            const int p1 = (p0 + 1 == P) ? 0 : p0 + 1;
            const int q1 = (p0 + 1 == P) ? q0 + 1 : q0;
            /* +1: the zero margin; rows iv and iv + 1, planes p0 and p1 */
            __global const float *r00 = texels + t.x + (p0 * t.z + iv + 1) * t.y + q0 + 1;
            __global const float *r01 = texels + t.x + (p1 * t.z + iv + 1) * t.y + q1 + 1;
            const float w00 = (1.0f - fu) * (1.0f - fv), w01 = fu * (1.0f - fv);
            const float w10 = (1.0f - fu) * fv, w11 = fu * fv;
            const float4 w = l_w[k];
#if CLW_PX == 16
            /* all 16 lanes read (the pool has 16 zeros before and 32 after it), masked lanes drop */
            const float16 sample = w00 * vload16(0, r00 + xbase) + w01 * vload16(0, r01 + xbase)
                                 + w10 * vload16(0, r00 + xbase + t.y) + w11 * vload16(0, r01 + xbase + t.y);
            const float16 masked = select((float16)(0.0f), sample,
                                          isgreaterequal(lane, (float16)(x0 - xbase)) &
                                          islessequal(lane, (float16)(x1 - xbase)));
            acc0 += w.x * masked;
            acc1 += w.y * masked;
            acc2 += w.z * masked;
            acc3 += w.w * masked;
#else
            for (int x = x0; x <= x1; ++x) {
                const float sample = w00 * r00[x] + w01 * r01[x] + w10 * r00[x + t.y] + w11 * r01[x + t.y];
                acc[x - xbase] += w * sample;
            }
#endif
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (y >= height)
        return;
#if CLW_PX == 16
    float a0[16], a1[16], a2[16], a3[16];
    vstore16(acc0, 0, a0);
    vstore16(acc1, 0, a1);
    vstore16(acc2, 0, a2);
    vstore16(acc3, 0, a3);
    for (int p = 0; p < 16; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += (float4)(a0[p], a1[p], a2[p], a3[p]);
#else
    for (int p = 0; p < CLW_PX; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += acc[p];
#endif
}
