/* blocks.cl: the largest |coefficient| that reaches each block of CLW_BLOCK^3 fine cells.
 *
 * Partition of unity: |f| <= max |c_i| over the coefficients whose B-splines touch a point, so a
 * block's value bounds every channel there.  The ray tracer (cl/raytrace/raytrace.cl) skips blocks whose
 * bound is below its per-ray share of the tolerance.  Blocks are in grid-0 fine coordinates; grid g
 * is shifted by (j_g - j_0) / 2 (docs/raytracing.md §3: orders of both parities have lattices half a cell apart).
 * Host: clwave/raytrace/tracer.py. */
#include "common/clw_common.h"

constant int ORDER[CLW_GROUPS] = {CLW_ORDERS};

/* block_max
 *   out          (Z, Y, X) float: bound per block, times the 0/1 support occupancy `occ`
 *   origin       block index of out[0, 0, 0], (x, y, z)
 *   coef, start, shape, offset   the fine grids as in raytrace.cl
 * Grid: global (X, Y, Z). */
__kernel void block_max(__global float *out, __global const uchar *occ, const int4 origin, const int4 nblocks,
                        __global const float4 *coef, __constant const int4 *start, __constant const int4 *shape,
                        __constant const int *offset)
{
    const int4 b = (int4)(get_global_id(0), get_global_id(1), get_global_id(2), 0);
    if (b.x >= nblocks.x || b.y >= nblocks.y || b.z >= nblocks.z)
        return;
    const size_t at = ((size_t)b.z * nblocks.y + b.y) * nblocks.x + b.x;
    float m = 0.0f;
    if (occ[at]) {
        for (int g = 0; g < CLW_GROUPS; g++) {
            const float shift = (float)(ORDER[g] - ORDER[0]) / 2;
            const int4 first = convert_int4(floor((float4)(convert_float4((b + origin) * CLW_BLOCK) + shift))) - ORDER[g] + 1;
            const int4 last = convert_int4(ceil((float4)(convert_float4((b + origin + 1) * CLW_BLOCK) + shift))) - 1;
            const int4 lo = max(first - start[g], 0), hi = min(last - start[g], shape[g] - 1);
            __global const float4 *base = coef + offset[g];
            for (int z = lo.z; z <= hi.z; z++)
                for (int y = lo.y; y <= hi.y; y++)
                    for (int x = lo.x; x <= hi.x; x++) {
                        const float4 c = fabs(base[((size_t)z * shape[g].y + y) * shape[g].x + x]);
                        m = fmax(m, fmax(fmax(c.x, c.y), fmax(c.z, c.w)));
                    }
        }
    }
    out[at] = m;
}
