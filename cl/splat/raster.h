/* raster.h: what both variants of splat_accumulate share (raster_cpu.cl, raster_gpu.cl):
 * accumulate the splats of each image tile (paper §4.1, eq. 29).
 *
 * Footprint textures are sampled at exactly 1/P pixel (P integer), so along an image row the
 * bilinear weights are the same for every pixel and pixel x reads texel ib + P x.  Each texture
 * is stored as P phase planes (plane p holds texels p, p + P, p + 2P, ... of every row), so a row
 * of pixels reads four contiguous runs of memory: the loop over x vectorises.  Along an axis
 * where a footprint is piecewise constant (Haar along a world axis) the texels are instead its
 * cells, looked up by nearest sample at any step (lookup bits of tex_int): cells along v pick
 * one texel row (weight 0 on the next), cells along u give each pixel its nearest column.  In a
 * magnified view, texels of more than a pixel (s_u < 1) are interpolated linearly per pixel from
 * one plane (lookup bit 2), so that textures need not grow with the magnification.
 *
 * splat_accumulate
 *   first_tile   the band's first tile, which the grid's work-items number from (clwave.device.kernels.in_bands)
 *   ranges   in  (tiles,) uint2: [start, end) into records
 *   records  in  (total, CLW_RECORD) uint4: splat records (cl/splat/record.h: centre, texture, the
 *                pixels in the tile, c per channel; the 2^{-m/2} is in the texture), sorted by
 *                tile, then texture, then importance
 *   tex_int  in  (T,) int4: (offset, columns per plane, rows per plane, lookup); planes carry
 *                a margin of zero texels: one column on either side, one row above and two
 *                below (a nearest row that rounds onto the bottom margin still reads its
 *                zero-weighted next row inside the plane).  lookup bit 0 (u) and bit 1 (v): set,
 *                the texels along that axis are samples at 1/P pixel, interpolated linearly
 *                (along u read from P phase planes, so the weights are the same for every pixel
 *                of a row); clear, they are cells at any texel step, looked up by nearest
 *                sample (along u gathered per pixel from one plane; clwave.splat.textures "cells"):
 *                exact for Haar footprints along a world axis, whose jumps lie on the cell
 *                edges, where linear interpolation would smear each jump over a texel.  Bit 2
 *                (with bit 0 clear): along u, samples of more than a pixel (s_u < 1), gathered
 *                per pixel from one plane and interpolated linearly (a magnified view)
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
 * Grid: one work-group per tile of all layers; the variants differ in who owns which pixels
 *   (raster_cpu.cl: one work-item per tile; raster_gpu.cl: CLW_PX pixels per work-item).
 * Assumes: each pixel is owned by one work-item and splats are visited in sorted order,
 *   so the image is bit-identical from run to run. */
#ifndef CLW_RASTER_H
#define CLW_RASTER_H
#include "splat/record.h"


/* Per splat, what does not depend on the pixel.  a: the lookup bits in a.w and the row stride
 * a.z; u from phase planes: the texel offsets of pixel 0 in the two phase planes (a.x, a.y; row
 * 0 of the padded plane) and the column weight f.x; u from one plane (cells, or bit 2: coarse
 * texels): a.x the start of row 0, a.y the column count (columns -1 and a.y are the zero margin),
 * f.x = centre_u (+ 1/2 for cells) and cell = (centre column, s_u).  f.y, f.z, f.w = centre row, texture centre row (+ 1/2 for v cells: floor gives
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
    } else {  /* one plane, gathered per pixel; cells: +1/2, floor gives the nearest texel */
        *a = (int4)(t.x + 1, t.y - 2, t.y, t.w);
        fx = (t.w & 4) ? m.x : m.x + 0.5f;
    }
    *f = (float4)(fx, c.y, (t.w & 2) ? m.y : m.y + 0.5f, m.w);
    *cell = (float2)(c.x, m.z);
}

/* the arguments of both variants of splat_accumulate (see the top of the file) */
#define ACCUMULATE_PARAMS const int first_tile, const int layer_count, __global const int4 *layers,                 \
    __global const uint2 *ranges, __global const uint4 *records, __global const int4 *tex_int,                      \
    __global const float4 *tex_map, __global const float *texels, __global float4 *fb

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

/* A cell lookup's position t (texels, floor gives the cell; cells are half-open, [k, k + 1)) at s texels per
 * pixel: within CLW_CELL_SNAP pixels of a cell edge, the edge itself.  Neighbouring Haar splats share their cells'
 * outer edges, and each places a pixel on such an edge by its own rounded centre: unsnapped, the pixel fell in both
 * cells (its line integral counted twice) or in neither (docs/splatting.md §1, "cells") */
inline float cell_position(const float t, const float s)
{
    const float e = rint(t);
    return fabs(t - e) <= CLW_CELL_SNAP * s ? e : t;
}

inline float16 cell_position16(const float16 t, const float s)
{
    const float16 e = rint(t);
    return select(t, e, islessequal(fabs(t - e), (float16)(CLW_CELL_SNAP * s)));
}

/* Image row y of a splat: its texel row (+1: the zero margin; rows iv, iv + 1) and v weight */
inline int splat_row(const int4 a, const float4 f, const int y, float *fv)
{
    float tv = f.z + (f.y - (float)y) * f.w;  /* image rows go down, v goes up */
    if (!(a.w & 2))
        tv = cell_position(tv, f.w);
    const float fiv = floor(tv);
    *fv = (a.w & 2) ? tv - fiv : 0.0f;
    return ((int)fiv + 1) * a.z;
}
#endif
