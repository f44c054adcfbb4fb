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
 *   ranges   in  (tiles,) uint2: [start, end) into records
 *   records  in  (total, CLW_RECORD) uint4: splat records (splat_record.h: centre, texture, the
 *                pixels in the tile, c per channel; the 2^{-m/2} is in the texture), sorted by
 *                tile, then texture, then importance
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
 *                texel steps per pixel (s_u, s_v); s_u = P for phase planes, and s_v = P too
 *                when both axes are linear (lookup 3), so the v weight is the same on every
 *                row of a splat
 *   texels   in  phase planes, (P, rows, columns) per texture; 16 zeros before the first
 *                and 32 after the last, so whole 16-pixel rows may be read
 *   layers   in  (L,) int4: (width, height, first tile, first pixel) of each framebuffer (layer);
 *                the tiles of layer l are first tile .. + tiles_x * tiles_y - 1, row by row
 *   fb       in/out float4: layer l's (height, width) pixels from its first pixel; the sum is
 *                added, so chunks accumulate
 * Build: -DCLW_CHANNELS=C (1..4) accumulates channels 0..C-1 only (the others of fb keep
 *   their values); the records hold C values.
 * Grid: one work-group per tile of all layers, local size CLW_TILE * CLW_TILE / CLW_PX.  CLW_PX = CLW_TILE^2
 *   (the default) suits PoCL: one work-item owns the tile and walks each splat's rows in it,
 *   16 pixels a vector, with the splat's set-up done once per tile rather than once per row
 *   (2.1x faster than a work-item per row on 2 EPYC cores).  CLW_PX = 1 (one pixel per item,
 *   the splats in batches through local memory) suits GPUs; work-item l owns CLW_PX
 *   consecutive pixels of row l / (CLW_TILE / CLW_PX).
 * Assumes: each pixel is owned by one work-item and splats are visited in sorted order,
 *   so the image is bit-identical from run to run. */
#include "splat_record.h"

#ifndef CLW_PX
#define CLW_PX (CLW_TILE * CLW_TILE)
#endif
#ifndef CLW_BATCH
#define CLW_BATCH 64
#endif

/* Per splat, what does not depend on the pixel.  a: the lookup bits in a.w and the row stride
 * a.z; u from phase planes: the texel offsets of pixel 0 in the two phase planes (a.x, a.y; row
 * 0 of the padded plane) and the column weight f.x; u cells: a.x the start of row 0, a.y the
 * column count (columns -1 and a.y are the zero margin), f.x = centre_u + 1/2 and cell = (centre
 * column, s_u).  f.y, f.z, f.w = centre row, texture centre row (+ 1/2 for v cells: floor gives
 * the nearest texel), s_v, from which each row finds its texel row. */
inline void splat_lookup(const int4 t, const float4 m, const float2 c, int4 *a, float4 *f, float2 *cell)
{
    float fx;
    if (t.w & 1) {
        const int P = (int)m.z;
        const float base = m.x - c.x * m.z;  /* texel of pixel x: base + P x */
        const float fib = floor(base);
        const int ib = (int)fib;
        /* phase plane p0 and column q0 of texel ib = q0 P + p0, 0 <= p0 < P: one division */
        const int qt = ib / P, rt = ib - qt * P;
        const int p0 = rt < 0 ? rt + P : rt, q0 = rt < 0 ? qt - 1 : qt;
        const int p1 = (p0 + 1 == P) ? 0 : p0 + 1;
        const int q1 = (p0 + 1 == P) ? q0 + 1 : q0;
        /* +1: the zero margin of the columns; the row margin is added per row */
        *a = (int4)(t.x + p0 * t.z * t.y + q0 + 1, t.x + p1 * t.z * t.y + q1 + 1, t.y, t.w);
        fx = base - fib;
    } else {  /* +1/2: floor gives the nearest texel */
        *a = (int4)(t.x + 1, t.y - 2, t.y, t.w);
        fx = m.x + 0.5f;
    }
    *f = (float4)(fx, c.y, (t.w & 2) ? m.y : m.y + 0.5f, m.w);
    *cell = (float2)(c.x, m.z);
}

/* the arguments of both layouts of splat_accumulate (see the top of the file) */
#define ACCUMULATE_PARAMS const int layer_count, __global const int4 *layers, __global const uint2 *ranges, \
    __global const uint4 *records, __global const int4 *tex_int, __global const float4 *tex_map,                \
    __global const float *texels, __global float4 *fb

/* The layer (width, height, first tile, first pixel) of a tile, and the tile's corner pixel in it */
inline int4 tile_layer(const int tile, const int layer_count, __global const int4 *layers, int2 *corner)
{
    int l = 0;
    while (l + 1 < layer_count && layers[l + 1].z <= tile)
        ++l;
    const int4 layer = layers[l];
    const int tiles_x = (layer.x + CLW_TILE - 1) / CLW_TILE, index = tile - layer.z;
    *corner = (int2)(index % tiles_x, index / tiles_x) * CLW_TILE;
    return layer;
}

/* Image row y of a splat: its texel row (+1: the zero margin; rows iv, iv + 1) and v weight */
inline int splat_row(const int4 a, const float4 f, const int y, float *fv)
{
    const float tv = f.z + (f.y - (float)y) * f.w;  /* image rows go down, v goes up */
    const float fiv = floor(tv);
    *fv = (a.w & 2) ? tv - fiv : 0.0f;
    return ((int)fiv + 1) * a.z;
}

#if CLW_PX == CLW_TILE * CLW_TILE
/* CPU: one work-item per tile, rows of 16 pixels as float16 vectors (PoCL vectorises these) */
#if CLW_TILE != 16
#error "the per-tile kernel works in rows of 16 pixels"
#endif
__kernel void splat_accumulate(ACCUMULATE_PARAMS)
{
    const int tile = get_global_id(0);
    int2 corner;
    const int4 layer = tile_layer(tile, layer_count, layers, &corner);
    const int width = layer.x, height = layer.y, xbase = corner.x, ybase = corner.y;
    fb += layer.w;
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    float16 acc[CLW_CHANNELS][CLW_TILE];
    for (int ch = 0; ch < CLW_CHANNELS; ++ch)
        for (int i = 0; i < CLW_TILE; ++i)
            acc[ch][i] = 0.0f;

    const uint2 r = ranges[tile];
    for (uint k = r.x; k < r.y; ++k) {
        int4 bx, a;  /* bx: the splat's pixels in the tile */
        float4 w, f;
        float2 cen, cs;
        const int tex = splat_unpack(records + k * CLW_RECORD, &cen, &bx, &w);
        splat_lookup(tex_int[tex], tex_map[tex], cen, &a, &f, &cs);
        const float c[4] = {w.x, w.y, w.z, w.w};  /* per channel, indexed in the channel loops */
        const int y0 = ybase + bx.y, y1 = ybase + bx.w;
        /* all 16 lanes read (the pool has 16 zeros before and 32 after it), masked lanes drop */
        const float16 mask = select((float16)(0.0f), (float16)(1.0f),
                                    isgreaterequal(lane, (float16)(bx.x)) & islessequal(lane, (float16)(bx.z)));
        float fv;
        const int row0 = splat_row(a, f, y0, &fv);
        if (a.w == 3) {
            /* bilinear from phase planes: the texel step along v is P rows per pixel (an integer),
             * so the four weights are those of row y0 for every row */
            const float fu = f.x;
            const float16 w00 = mask * ((1.0f - fu) * (1.0f - fv)), w01 = mask * (fu * (1.0f - fv));
            const float16 w10 = mask * ((1.0f - fu) * fv), w11 = mask * (fu * fv);
            const int step = (int)f.w * a.z;
            __global const float *r0 = texels + a.x + row0 + xbase;
            __global const float *r1 = texels + a.y + row0 + xbase;
            for (int y = y0; y <= y1; ++y, r0 -= step, r1 -= step) {
                const float16 sample = fma(w00, vload16(0, r0), fma(w01, vload16(0, r1),
                                       fma(w10, vload16(0, r0 + a.z), w11 * vload16(0, r1 + a.z))));
                for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                    acc[ch][y - ybase] = fma((float16)(c[ch]), sample, acc[ch][y - ybase]);
            }
            continue;
        }
        for (int y = y0; y <= y1; ++y) {  /* a cell axis (Haar along a world axis) */
            const int row = splat_row(a, f, y, &fv);
            __global const float *r00 = texels + a.x + row;
            float16 sample;
            if (a.w & 1) {
                __global const float *r01 = texels + a.y + row;
                sample = (1.0f - fv) * ((1.0f - f.x) * vload16(0, r00 + xbase) + f.x * vload16(0, r01 + xbase))
                       + fv * ((1.0f - f.x) * vload16(0, r00 + xbase + a.z) + f.x * vload16(0, r01 + xbase + a.z));
            } else {  /* u cells: each lane takes its nearest column (a.y of them, a handful: 2 for
                       * footprints), by selects rather than gathers; lanes off the texture keep 0 */
                const int16 col = convert_int16(floor(f.x + (((float16)((float)xbase) + lane) - cs.x) * cs.y));
                sample = 0.0f;
                for (int q = 0; q < a.y; ++q) {
                    const float cell = (1.0f - fv) * r00[q] + fv * r00[q + a.z];
                    sample = select(sample, (float16)(cell), col == (int16)(q));
                }
            }
            for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                acc[ch][y - ybase] = fma((float16)(c[ch]), mask * sample, acc[ch][y - ybase]);
        }
    }
    for (int i = 0; i < CLW_TILE && ybase + i < height; ++i) {
        float out[4][16] = {{0}};
        for (int ch = 0; ch < CLW_CHANNELS; ++ch)
            vstore16(acc[ch][i], 0, out[ch]);
        for (int p = 0; p < 16 && xbase + p < width; ++p)
            fb[(ybase + i) * width + xbase + p] += (float4)(out[0][p], out[1][p], out[2][p], out[3][p]);
    }
}
#else
/* GPUs: CLW_PX consecutive pixels of a row per work-item (1: one pixel each), a work-group per
 * tile, the tile's splats in batches through local memory */
#define CLW_ITEMS_PER_ROW (CLW_TILE / CLW_PX)
__kernel void splat_accumulate(ACCUMULATE_PARAMS)
{
    __local int4 l_box[CLW_BATCH];
    __local int4 l_addr[CLW_BATCH];
    __local float4 l_f[CLW_BATCH];
    __local float4 l_w[CLW_BATCH];
    __local float2 l_cell[CLW_BATCH];

    const int tile = get_group_id(0);
    const int lid = get_local_id(0);
    const int nitems = get_local_size(0);
    int2 origin;
    const int4 layer = tile_layer(tile, layer_count, layers, &origin);
    const int width = layer.x, height = layer.y;
    fb += layer.w;
    const int4 corner = (int4)(origin, origin);
    const int y = corner.y + lid / CLW_ITEMS_PER_ROW;
    const int xbase = corner.x + (lid % CLW_ITEMS_PER_ROW) * CLW_PX;
    float4 acc[CLW_PX];
    for (int p = 0; p < CLW_PX; ++p)
        acc[p] = (float4)(0.0f);

    const uint2 r = ranges[tile];
    for (uint b0 = r.x; b0 < r.y; b0 += CLW_BATCH) {
        const uint nb = min((uint)CLW_BATCH, r.y - b0);
        for (uint k = lid; k < nb; k += nitems) {
            int4 a, bx;
            float4 f, w;
            float2 cen, cs;
            const int tex = splat_unpack(records + (b0 + k) * CLW_RECORD, &cen, &bx, &w);
            splat_lookup(tex_int[tex], tex_map[tex], cen, &a, &f, &cs);
            l_addr[k] = a;
            l_f[k] = f;
            l_cell[k] = cs;
            l_box[k] = corner + bx;
            l_w[k] = w;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (uint k = 0; k < nb; ++k) {
            const int4 bx = l_box[k];
            const int x0 = max(bx.x, xbase), x1 = min(bx.z, xbase + CLW_PX - 1);
            if (y < bx.y || y > bx.w || x0 > x1)
                continue;
            const int4 a = l_addr[k];
            const float4 f = l_f[k];
            const float2 cs = l_cell[k];
            float fv;
            const int row = splat_row(a, f, y, &fv);
            __global const float *r00 = texels + a.x + row;
            __global const float *r01 = texels + a.y + row;
            for (int x = x0; x <= x1; ++x) {
                float sample;
                if (a.w & 1) {
                    sample = (1.0f - fv) * ((1.0f - f.x) * r00[x] + f.x * r01[x])
                           + fv * ((1.0f - f.x) * r00[x + a.z] + f.x * r01[x + a.z]);
                } else {
                    const int col = clamp((int)floor(f.x + ((float)x - cs.x) * cs.y), -1, a.y);
                    sample = (1.0f - fv) * r00[col] + fv * r00[col + a.z];
                }
                acc[x - xbase] += l_w[k] * sample;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (y >= height)
        return;
    for (int p = 0; p < CLW_PX; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += acc[p];
}
#endif
