/* cl/splat/bin.cl: project splats and bin them into image tiles (paper §4, docs/splatting.md §2).
 *
 * Pipeline (host: clwave/splat/stages.py): splat_project -> splat_chunk_tiles counting (per chunk
 * of consecutive splats, a count per tile and texture) -> transpose_counts -> exclusive scan
 * of the counts in (tile, texture, chunk) order -> tile_ranges -> transpose_counts ->
 * splat_chunk_tiles placing.  Each chunk keeps its own counts together (chunk-major), so a
 * CPU core finds them in its cache; the scan wants them run-major.  This is a counting
 * sort by tile and, within a tile, by texture: each chunk writes its splats, in splat order, at
 * its own offsets within each (tile, texture) run, so the sum is deterministic, with no
 * atomics.  Texture order within a tile keeps one footprint's texels in cache while they are
 * used (docs/splatting.md §3).  The tiles of all of a
 * frame's framebuffers (layers) are numbered one after the other, so one pass bins them all. */
#include "splat/record.h"

/* splat_project: centre, pixel box and tile count of each splat.
 *
 * The bands of one frame are drawn into one or more framebuffers (layers: the image's pixel, or
 * coarser ones, clwave.splat.coarse.Layer), each cut into its own tiles; a splat's texture says which.
 *
 * Parameters
 *   n            number of splats in this chunk
 *   first        index of the chunk's first coefficient
 *   coef         in  (K,) int4: (k_x, k_y, k_z, band), band = level * 8 + subband code
 *   band_tex     in  (64,) int: texture of each band, -1 when its footprint vanishes or it is not drawn
 *   band_origin  in  (64,) float2: pixel (col, row) of the centre of coefficient k = 0, in its layer
 *   step_col     in  (64,) float4: d col / d (k_x, k_y, k_z) per band, in its layer's pixels
 *   step_row     in  (64,) float4: d row / d (k_x, k_y, k_z) per band
 *   tex_box      in  (T,) float4: texture box in pixels around the centre (a_min, a_max, b_min, b_max)
 *   tex_layer    in  (T,) int2: the texture's layer and its index among that layer's textures
 *   layers       in  (L,) int4: (width, height, first tile, first pixel) of each layer
 *   centre       out (n,) float2: pixel (col, row) of the support centre
 *   bbox         out (n,) int4: covered pixels (x0, y0, x1, y1) of its layer, inclusive; x1 < x0 when empty
 *   stex         out (n,) int: texture id
 *   count        out (n,) uint: number of tiles the box touches
 * Grid: global (n,), any local size.  (Perspective builds project in cl/splat/cone.cl.) */
#ifndef CLW_PERSPECTIVE
__kernel void splat_project(const uint n, const uint first, __global const int4 *coef,
                            __global const int *band_tex, __global const float2 *band_origin,
                            __global const float4 *step_col, __global const float4 *step_row,
                            __global const float4 *tex_box, __global const int2 *tex_layer,
                            __global const int4 *layers, __global float2 *centre, __global int4 *bbox,
                            __global int *stex, __global uint *count)
{
    const uint i = get_global_id(0);
    if (i >= n)
        return;
    const int4 c = coef[first + i];
    const int tex = band_tex[c.w];
    const float4 sc = step_col[c.w], sr = step_row[c.w];
    const float2 o = band_origin[c.w];
    const float col = ((o.x + (float)c.x * sc.x) + (float)c.y * sc.y) + (float)c.z * sc.z;
    const float row = ((o.y + (float)c.x * sr.x) + (float)c.y * sr.y) + (float)c.z * sr.z;
    int4 box = (int4)(0, 0, -1, -1);
    uint cnt = 0;
    if (tex >= 0) {
        const float4 b = tex_box[tex];
        const int4 layer = layers[tex_layer[tex].x];
        /* pixel centres inside the texture box; rows grow downwards while v points up */
        const float x0 = fmax(ceil(col + b.x), 0.0f), x1 = fmin(floor(col + b.y), (float)(layer.x - 1));
        const float y0 = fmax(ceil(row - b.w), 0.0f), y1 = fmin(floor(row - b.z), (float)(layer.y - 1));
        if (x0 <= x1 && y0 <= y1) {
            box = (int4)((int)x0, (int)y0, (int)x1, (int)y1);
            cnt = (uint)((box.z / CLW_TILE - box.x / CLW_TILE + 1) * (box.w / CLW_TILE - box.y / CLW_TILE + 1));
        }
    }
    centre[i] = (float2)(col, row);
    bbox[i] = box;
    stex[i] = tex;
    count[i] = cnt;
}
#endif

/* splat_chunk_tiles: walk the tiles each splat of a chunk touches, to count or to place them.
 *   n            number of splats; chunk c holds splats c * chunk .. c * chunk + chunk - 1
 *   tiles        number of tiles of all layers (layer l's tile (tx, ty) is first tile + ty * tiles_x + tx)
 *   textures     the most textures of any layer (runs are keyed by the index within the layer)
 *   place        0: count, 1: place
 *   first        index of the chunk's first coefficient (values are indexed first + splat)
 *   lo, hi       this launch walks splats lo .. hi - 1 of each chunk (of its own numbering): long passes
 *                go in several launches, each continuing the counts or cursors of the last
 *                (clwave.device.kernels.in_bands), so Ctrl-C is taken between them
 *   bbox, stex   in  (n,) from splat_project; centre too (read when placing; float4 with its depth in
 *                perspective builds, cl/splat/record.h)
 *   values       in  (K,) float4: coefficient per channel
 *   tex_layer, layers  in  as for splat_project
 *   table        (chunks, tiles, textures) uint.  counting: out, [(c * tiles + tile) * textures + j]
 *                = how many splats of chunk c with texture j of their layer touch the tile;  placing: in/out,
 *                where chunk c writes next in each (tile, texture) run (consumed): the exclusive
 *                scan of the counts in (tile, texture, chunk) order, back in this layout
 *   records      placing: out (total, CLW_RECORD) uint4, one splat record per (tile, splat) pair
 *                (cl/splat/record.h), by tile, texture and splat.  Records rather than splat
 *                indices: the accumulation then reads each tile's list front to back instead of
 *                the splats' tables at random (those misses took 40 % of its time)
 * Grid: global (chunks,), any local size; work-item c owns row c of table. */
__kernel void splat_chunk_tiles(const uint n, const uint chunk, const uint chunks, const uint tiles,
                                const uint textures, const int place, const uint first, const uint lo,
                                const uint hi,
                                __global const int4 *bbox, __global const CLW_CENTRE *centre, __global const int *stex,
                                __global const float4 *values, __global const int2 *tex_layer,
                                __global const int4 *layers, __global uint *table, __global uint4 *records)
{
    const uint c = get_global_id(0);
    if (c >= chunks)
        return;
    if (!place && lo == 0)
        for (uint t = 0; t < tiles * textures; ++t)
            table[c * tiles * textures + t] = 0;
    const uint end = min(min(n, (c + 1) * chunk), c * chunk + hi);
    for (uint i = c * chunk + lo; i < end; ++i) {
        const int4 b = bbox[i];
        if (b.z < b.x)
            continue;
        const int tex = stex[i];
        const int2 tl = tex_layer[tex];
        const int4 layer = layers[tl.x];
        const int tiles_x = (layer.x + CLW_TILE - 1) / CLW_TILE;
        for (int ty = b.y / CLW_TILE; ty <= b.w / CLW_TILE; ++ty)
            for (int tx = b.x / CLW_TILE; tx <= b.z / CLW_TILE; ++tx) {
                const uint tile = (uint)(layer.z + ty * tiles_x + tx);
                __global uint *slot = table + (c * tiles + tile) * textures + (uint)tl.y;
                if (place)
                    splat_record(records + (*slot)++ * CLW_RECORD, b - (int4)(tx, ty, tx, ty) * CLW_TILE, centre[i],
                                 tex, values[first + i]);
                else
                    ++*slot;
            }
    }
}

/* tile_ranges: [start, end) of each tile's run from the scanned counts.
 *   offset  in  (tiles, textures, chunks) uint: exclusive scan of the counts in that order
 *   total   number of (tile, splat) pairs
 *   ranges  out (tiles,) uint2
 * Grid: global (tiles,). */
__kernel void tile_ranges(const uint tiles, const uint textures, const uint chunks, const uint total,
                          __global const uint *offset, __global uint2 *ranges)
{
    const uint t = get_global_id(0);
    if (t >= tiles)
        return;
    const uint run = textures * chunks;  /* the counts of one tile */
    ranges[t] = (uint2)(offset[t * run], t + 1 < tiles ? offset[(t + 1) * run] : total);
}

/* transpose_counts: dst (cols, rows) = src (rows, cols) transposed, uint.  Grid: global (rows * cols,). */
__kernel void transpose_counts(const uint rows, const uint cols, __global const uint *src, __global uint *dst)
{
    const uint i = get_global_id(0);
    if (i < rows * cols)
        dst[(i % cols) * rows + i / cols] = src[i];
}
