/* scalar.cl: what post-classification needs of a scalar model's brick pool (clwave/raytrace/classified.py,
 * docs/raytracing.md §8): the range of the scalar per block, and a strided sample of its coefficients. */
#include "common/clw_common.h"

/* scalar_range: per block of CLW_BLOCK^3 grid-0 fine cells of every brick, the least and largest
 * coefficient (channel 0) whose B-spline reaches it: the B-splines are non-negative and sum to 1, so the
 * scalar lies between them there.
 *   out          (Z, Y, X) float2 (min, max) over the page table's box, zero in blocks of no brick
 *   nblocks, origin, coef, bricks, frames, boxes   as brick_bounds (cl/raytrace/bricks.cl), one group
 * Grid: global ((CLW_SUPER_CELLS / CLW_BLOCK)^3, slots). */
__kernel void scalar_range(__global float2 *out, const int4 nblocks, const int4 origin, __global const float4 *coef,
                           __global const int4 *bricks, __global const float4 *frames, __global const int4 *boxes,
                           const int order)
{
    const int per = CLW_SUPER_CELLS / CLW_BLOCK, k = get_global_id(0), slot = get_global_id(1);
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
                const float c = coef[n.w + ((size_t)z * n.y + y) * n.x + x].x;
                m = (float2)(fmin(m.x, c), fmax(m.y, c));
            }
    out[((size_t)block.z * nblocks.y + block.y) * nblocks.x + block.x] = m;
}

/* strided: out[i] = coef[i * step].x, the scalar coefficients of a strided sample of the pool.
 * Grid: global (n). */
__kernel void strided(__global float *out, __global const float4 *coef, const long step, const int n)
{
    const int i = get_global_id(0);
    if (i < n)
        out[i] = coef[i * step].x;
}
