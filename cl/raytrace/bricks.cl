/* bricks.cl: the brick pool of the ray tracer's B-spline field (clwave/raytrace/bricks.py,
 * docs/raytracing.md §3): a band's kept coefficients into the box a slab's synthesis reads, copying each
 * brick's lattice coefficients out of that synthesis, and the bounds on |field| per CLW_BLOCK^3 block
 * of the bricks for empty-space skipping (§4). */
#include "common/clw_common.h"

constant int ORDER[CLW_GROUPS] = {CLW_ORDERS};

/* The pool's coefficient: a float4, each channel in its lane, or with CLW_POOL_SCALAR a float, the channel of a
 * model of one channel alone (its pool packed by post-classification, clwave/raytrace/classified.py). */
#ifdef CLW_POOL_SCALAR
typedef float pool_coef;
inline float coef_abs_max(const float c) { return fabs(c); }
#else
typedef float4 pool_coef;
inline float coef_abs_max(const float4 c)
{
    const float4 a = fabs(c);
    return fmax(fmax(a.x, a.y), fmax(a.z, a.w));
}
#endif

/* scatter_band: a band's kept coefficients into a zeroed box of `lanes` floats a coefficient (4, or 1 for a group
 * of one channel: expand.cl's CLW_LANES), each channel in its slot.
 *   out, out_start, out_shape   a box of lanes floats in the band's index coordinates (x, y, z)
 *   positions    (n,) flat positions in the band (row-major over band_shape, x fastest), from band_start
 *   values       (channels, n) their values, channel by channel
 *   slots        the lane of channel c in component c (x, y, z, w); channels > c
 * Grid: global (n). */
__kernel void scatter_band(__global float *out, const int4 out_start, const int4 out_shape,
                           __global const long *positions, const long band_start, const int4 band_shape,
                           __global const float *values, const int n, const int4 slots, const int channels,
                           const int lanes)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const long p = positions[i] - band_start, plane = (long)band_shape.x * band_shape.y;
    const int z = (int)(p / plane), y = (int)(p % plane / band_shape.x), x = (int)(p % band_shape.x);
    const int4 k = (int4)(x, y, z, 0) - out_start;
    if (k.x < 0 || k.y < 0 || k.z < 0 || k.x >= out_shape.x || k.y >= out_shape.y || k.z >= out_shape.z)
        return;
    const size_t at = lanes * (((size_t)k.z * out_shape.y + k.y) * out_shape.x + k.x);
    const int slot[4] = {slots.x, slots.y, slots.z, slots.w};
    for (int c = 0; c < channels; c++)
        out[at + slot[c]] = values[(size_t)c * n + i];
}

/* gather_bricks: pool[box.w + local index] = scale * src[start + local index], zero outside src (CLW_POOL_SCALAR:
 * its lane `lane` alone).
 *   src, src_start, src_shape   one level's synthesis over a slab: a box of float4 (x, y, z), or of float
 *                (lane >= 0: a group of one channel, expand.cl's CLW_LANES = 1) put in component `lane`, the others 0
 *   starts       per brick the lattice index (x, y, z) of its first coefficient
 *   boxes        per brick (nx, ny, nz, first pool element)
 *   depth        the largest nz: work-items depth * b .. depth * (b + 1) - 1 along axis 2 copy brick b
 *   scale        2^(-3 l / 2): the level-l B-splines' normalisation (docs/model.md §4)
 * Grid: global (max nx, max ny, depth * bricks). */
__kernel void gather_bricks(__global pool_coef *pool, __global const float *src, const int4 src_start,
                            const int4 src_shape, __global const int4 *starts, __global const int4 *boxes,
                            const int depth, const float scale, const int lane)
{
    const int b = get_global_id(2) / depth;
    const int4 at = (int4)(get_global_id(0), get_global_id(1), get_global_id(2) % depth, 0), box = boxes[b];
    if (at.x >= box.x || at.y >= box.y || at.z >= box.z)
        return;
    const int4 p = starts[b] + at - src_start;
    const bool inside = p.x >= 0 && p.y >= 0 && p.z >= 0 && p.x < src_shape.x && p.y < src_shape.y && p.z < src_shape.z;
    const size_t i = inside ? ((size_t)p.z * src_shape.y + p.y) * src_shape.x + p.x : 0;
    float4 v = lane < 0 ? vload4(i, src) : select((float4)(0.0f), (float4)(src[i]), (int4)(0, 1, 2, 3) == lane);
    v = inside ? v : (float4)(0.0f);
    const size_t out = box.w + ((size_t)at.z * box.y + at.y) * box.x + at.x;
#ifdef CLW_POOL_SCALAR
    pool[out] = scale * v.x;
#else
    pool[out] = scale * v;
#endif
}

/* brick_bounds: per block of CLW_BLOCK^3 grid-0 fine cells of every brick, the largest |coefficient|
 * of any group whose B-spline reaches it (partition of unity: |f| <= max |c| there, every channel).
 *   out          (slots, per, per, per) float, per = CLW_SUPER_CELLS / CLW_BLOCK blocks along a brick's edge
 *                (z, y, x): the blocks of each slot, whatever detail it serves (clwave/raytrace/lod.py)
 *   first        out's slot of the launch's slot 0 (a slab's slots are consecutive)
 *   origin       the brick index (x, y, z) of the page table's first brick
 *   coef, frames, boxes   the pool as in field_bspline.h; bricks: per slot its brick (x, y, z) in the
 *                page table
 * Grid: global (per^3, slots). */
__kernel void brick_bounds(__global float *out, const int first, const int4 origin, __global const pool_coef *coef,
                           __global const int4 *bricks, __global const float4 *frames, __global const int4 *boxes)
{
    const int per = CLW_SUPER_CELLS / CLW_BLOCK, k = get_global_id(0), slot = get_global_id(1);
    const int4 block = bricks[slot] * per + (int4)(k % per, k / per % per, k / (per * per), 0);
    const float4 lo = convert_float4((block + origin * per) * CLW_BLOCK), hi = lo + CLW_BLOCK;
    float m = 0.0f;
    for (int g = 0; g < CLW_GROUPS; g++) {
        const float4 f = frames[slot * CLW_GROUPS + g];
        const int4 n = boxes[slot * CLW_GROUPS + g];
        const int4 first = max(convert_int4(floor((lo - f) * f.w)) - ORDER[g] + 1, 0);
        const int4 last = min(convert_int4(ceil((hi - f) * f.w)) - 1, n - 1);
        for (int z = first.z; z <= last.z; z++)
            for (int y = first.y; y <= last.y; y++)
                for (int x = first.x; x <= last.x; x++)
                    m = fmax(m, coef_abs_max(coef[n.w + ((size_t)z * n.y + y) * n.x + x]));
    }
    out[(size_t)(first + slot) * per * per * per + k] = m;
}

#ifndef CLW_POOL_SCALAR
/* alpha_floor: per slot the least alpha (channel 3, lane w) coefficient of group `g` of the brick: the
 * B-splines are non-negative and sum to 1, so alpha >= that floor in the brick.
 * Grid: global (slots). */
__kernel void alpha_floor(__global float *out, __global const float4 *coef, __global const int4 *boxes, const int g)
{
    const int slot = get_global_id(0);
    const int4 n = boxes[slot * CLW_GROUPS + g];
    float m = INFINITY;
    for (size_t i = 0; i < (size_t)n.x * n.y * n.z; i++)
        m = fmin(m, coef[n.w + i].w);
    out[slot] = m;
}
#endif
