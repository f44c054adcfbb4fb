/* scalar.cl: what post-classification needs of a scalar model's brick pool (clwave/raytrace/classified.py,
 * docs/raytracing.md §10): the range of the scalar per block. */
#include "common/clw_common.h"
typedef float real; /* the table's precision here (tf_table.h) */
typedef float4 real4;
#include "raytrace/tf_table.h"

/* scalar_range: per block of CLW_BLOCK^3 grid-0 fine cells of every brick slot (whatever detail it serves), the
 * least and largest coefficient whose B-spline reaches it: the B-splines are non-negative and sum to 1, so the
 * scalar lies between them there.
 *   out          (slots, per, per, per) float2 (min, max), per = CLW_SUPER_CELLS / CLW_BLOCK blocks along a
 *                brick's edge (z, y, x), as brick_bounds lays out its bounds (cl/raytrace/bricks.cl)
 *   origin, coef, bricks, frames, boxes   as brick_bounds, one group, the pool one float a coefficient
 *                (CLW_POOL_SCALAR of cl/raytrace/bricks.cl)
 * Grid: global ((CLW_SUPER_CELLS / CLW_BLOCK)^3, slots) from slot first_slot (a band of slots). */
__kernel void scalar_range(__global float2 *out, const int first_slot, const int4 origin, __global const float *coef,
                           __global const int4 *bricks, __global const float4 *frames, __global const int4 *boxes,
                           const int order)
{
    const int per = CLW_SUPER_CELLS / CLW_BLOCK, k = get_global_id(0), slot = first_slot + get_global_id(1);
    const int4 block = bricks[slot] * per + (int4)(k % per, k / per % per, k / (per * per), 0);
    const float4 lo = convert_float4((block + origin * per) * CLW_BLOCK), hi = lo + CLW_BLOCK;
    const float4 f = frames[slot];
    const int4 n = boxes[slot];
    const int4 first = max(convert_int4(floor((lo - f) * f.w)) - order + 1, 0);
    const int4 last = min(convert_int4(ceil((hi - f) * f.w)) - 1, n - 1);
    float2 m = (float2)(INFINITY, -INFINITY);
    for (int z = first.z; z <= last.z; z++)
        for (int y = first.y; y <= last.y; y++)
            for (int x = first.x; x <= last.x; x++) {
                const float c = coef[n.w + ((size_t)z * n.y + y) * n.x + x];
                m = (float2)(fmin(m.x, c), fmax(m.y, c));
            }
    out[(size_t)slot * per * per * per + k] = m;
}

/* classified_bounds: per block the largest opacity of the transfer function over the block's range
 * [min - slack, max + slack] (tf_peak).
 *   bound   out (n,) float; range (n,) float2 from scalar_range; tf the table (float, tf_table.h)
 * Grid: global (n). */
__kernel void classified_bounds(__global float *bound, __global const float2 *range, __global const float4 *tf,
                                const float slack, const int n)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const float4 head = tf[0];
    bound[i] = tf_peak(tf, (int)head.z, (range[i].x - slack) * head.x + head.y, (range[i].y + slack) * head.x + head.y);
}

/* superblock_max: per superblock of CLW_SUPER_CELLS / CLW_BLOCK blocks a side, the largest block bound (the
 * blocks' origin a whole number of superblocks).
 *   out (S, S, S shape ns) float; bound (nb) float over the blocks
 * Grid: global (ns.x, ns.y, ns.z). */
__kernel void superblock_max(__global float *out, const int4 ns, __global const float *bound, const int4 nb)
{
    const int per = CLW_SUPER_CELLS / CLW_BLOCK;
    const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
    if (x >= ns.x || y >= ns.y || z >= ns.z)
        return;
    float m = 0.0f;
    for (int c = z * per; c < min(z * per + per, nb.z); c++)
        for (int b = y * per; b < min(y * per + per, nb.y); b++)
            for (int a = x * per; a < min(x * per + per, nb.x); a++)
                m = fmax(m, bound[((size_t)c * nb.y + b) * nb.x + a]);
    out[((size_t)z * ns.y + y) * ns.x + x] = m;
}
