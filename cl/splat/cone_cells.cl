/* cl/splat/cone_cells.cl: a perspective view's slope cells (the texel pool cl/splat/cone.cl reads) made on the
 * device from its footprints at the slope nodes, docs/splatting.md §8 "Cost".  NumPy oracle:
 * clwave.splat.reference.slope_cells.
 *
 * The host uploads each texture's nodes, (K, nv, nu) float32 with K = ku kv row-major by v (a texture refined r
 * times, cone.cl's tex_int.z, has ku = (k_u - 1) r + 1 of the grid's k_u, and so along v); a cell of its nodes is
 * one block of (nv + 2, nu + 2) texels of 4 floats (its four nodes interleaved, a zero margin all round:
 * cone.cl's tex_int), 4 (ku - 1)(kv - 1) / (ku kv) times the nodes' floats, so the pool is written here rather
 * than uploaded.  With quasi != 0 each node's value is stored less 1/16 of its second differences along the slope
 * axes of three nodes or more (at either end the nearest one's; clwave.splat.perspective.quasi_interpolant, the
 * same float32 operations in the same order).  peaks[first + k]: the largest magnitude of texture t's stored values
 * at its node k (float bits; cells' bounds for dropped splats), first its tex_nodes.z. */
#include "common/clw_common.h"

/* The rows a node's stored value is made of: its own, and the three of its second difference along v and along u
 * (at j = clamp(node, 1, k - 2)); an axis of fewer than 3 nodes gets its own row three times, whose (x + x) - 2 x
 * is exactly 0, so the loop has no branch but quasi's */
typedef struct {
    __global const float *self, *v_lo, *v_mid, *v_hi, *u_lo, *u_mid, *u_hi;
} node_rows;

/* node (a, b) at x + (b ku + a) plane */
inline node_rows rows_of(__global const float *x, const size_t plane, const int a, const int b, const int ku,
                         const int kv)
{
    node_rows r;
    r.self = r.v_lo = r.v_mid = r.v_hi = r.u_lo = r.u_mid = r.u_hi = x + (b * ku + a) * plane;
    if (kv >= 3) {
        const int j = clamp(b, 1, kv - 2);
        r.v_lo = x + ((j - 1) * ku + a) * plane;
        r.v_mid = x + (j * ku + a) * plane;
        r.v_hi = x + ((j + 1) * ku + a) * plane;
    }
    if (ku >= 3) {
        const int j = clamp(a, 1, ku - 2);
        r.u_lo = x + (b * ku + j - 1) * plane;
        r.u_mid = x + (b * ku + j) * plane;
        r.u_hi = x + (b * ku + j + 1) * plane;
    }
    return r;
}

/* The value stored at texel i: less 1/16 of the correction, along v and then along u added (the host's order) */
inline float stored(const node_rows r, const int i)
{
    const float correction = ((r.v_hi[i] + r.v_lo[i]) - 2.0f * r.v_mid[i]) + ((r.u_hi[i] + r.u_lo[i]) - 2.0f * r.u_mid[i]);
    return r.self[i] - correction * 0.0625f;
}

/* cone_cells
 *
 * Parameters
 *   textures   in  the number of textures
 *   ku, kv     in  the slope grid's nodes along u, v
 *   quasi      in  store quasi-interpolants along the slope axes (smooth footprints)
 *   tex_int    in  (T,) int4: cone.cl's (offset of cell 0's first texel in floats, row stride nu + 2, slope
 *                  refinement r, rows nv + 2)
 *   tex_nodes  in  (T,) int4: (the texture's first work-item, the offset of its nodes in floats, of its first
 *                  node's peak, 0)
 *   nodes      in  every texture's nodes
 *   texels     out the pool (its guards are the host's)
 *   peaks      in/out uint: zeros in; each node's largest magnitude (float bits) out, each texture's K in order
 * Grid: a work-item per row of a cell, (ku - 1)(kv - 1)(nv + 2) a texture (its own ku, kv) in order, rounded up to
 * whole groups. */
__kernel void cone_cells(const int textures, const int grid_u, const int grid_v, const int quasi,
                         __global const int4 *tex_int, __global const int4 *tex_nodes,
                         __global const float *restrict nodes, __global float *restrict texels,
                         __global uint *restrict peaks)
{
    const int item = get_global_id(0);
    int t = 0;
    while (t + 1 < textures && tex_nodes[t + 1].x <= item)
        ++t;
    const int4 ti = tex_int[t];
    const int ku = (grid_u - 1) * ti.z + 1, kv = (grid_v - 1) * ti.z + 1;  /* its own nodes */
    const int r = item - tex_nodes[t].x;
    if (r >= (ku - 1) * (kv - 1) * ti.w)
        return;
    const int nu = ti.y - 2, nv = ti.w - 2, cell = r / ti.w, iv = r - cell * ti.w - 1;
    const int cv = cell / (ku - 1), cu = cell - cv * (ku - 1);
    __global float4 *out = (__global float4 *)(texels + ti.x + cell * 4 * ti.y * ti.w) + (iv + 1) * ti.y;
    out[0] = out[nu + 1] = (float4)(0.0f);
    if (iv < 0 || iv >= nv) {
        for (int i = 1; i <= nu; ++i)
            out[i] = (float4)(0.0f);
        return;
    }
    const size_t plane = (size_t)nu * nv;
    __global const float *x = nodes + tex_nodes[t].y + (size_t)iv * nu;
    const node_rows r00 = rows_of(x, plane, cu, cv, ku, kv), r10 = rows_of(x, plane, cu + 1, cv, ku, kv);
    const node_rows r01 = rows_of(x, plane, cu, cv + 1, ku, kv);
    const node_rows r11 = rows_of(x, plane, cu + 1, cv + 1, ku, kv);
    float4 most = (float4)(0.0f);
    for (int i = 0; i < nu; ++i) {
        const float4 v = quasi ? (float4)(stored(r00, i), stored(r10, i), stored(r01, i), stored(r11, i))
                               : (float4)(r00.self[i], r10.self[i], r01.self[i], r11.self[i]);
        out[i + 1] = v;
        most = fmax(most, fabs(v));
    }
    __global uint *p = peaks + tex_nodes[t].z + cv * ku + cu;
    atomic_max(p, as_uint(most.x));
    atomic_max(p + 1, as_uint(most.y));
    atomic_max(p + ku, as_uint(most.z));
    atomic_max(p + ku + 1, as_uint(most.w));
}
