/* classify_check.cl: a post-classified segment (classify.h: post_segment, then post_gradient) on given segments, for
 * its test against an independent quadrature (tests/test_classify.py).  Build with CLW_POST, CLW_SAMPLES,
 * CLW_GROUPS, CLW_ORDERS, CLW_MAX_DEPTH, and CLW_SHADE for Phong shading by one light.
 *   out      (n,) real4: int q' e^{-A} dxi (rgb) and int alpha dxi over xi in [-1, 1]
 *   samples  (n, CLW_SAMPLES) the scalar at the sample points (lane order of the ray tracer's fq)
 *   grads    (n, 3, 16) its gradient (fine units) at the lanes 0..NG-1, per axis
 *   radius   (n,) half the segment length; nodes, weights, tf as in raytrace.cl; tol on the emission (xi units)
 *   shading  (ka, kd, ks, shininess, the light's direction (3), the halfway vector (3), the flat gradients' floor)
 *   budget   (n,) the shading budget (xi units: the segment's weight is 1), replaced by what is left of it
 *   stats    (n,) int4: flags (bit 1: a span or panel at its depth limit), shaded at the midpoint, inside one
 *            interval, integrand evaluations
 * Grid: global (n).
 * And unpack_pool, unpack_cells: a packed scalar pool's q through the ray tracer's decode (scalar_pool.h), for
 * its test. */
#include "raytrace/types.h"
#include "raytrace/classify.h"
#include "raytrace/scalar_pool.h"

__kernel void classify_segments(__global real4 *out, __global const real *samples, __global const real *grads,
                                __global const real *radius, __constant const real *nodes,
                                __constant const real *weights, __global const real4 *tf, const real tol,
                                __global const real *shading, __global real *budget, __global int4 *stats, const int n)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    real s[NS], u[NS], c[NS];
    for (int k = 0; k < NS; k++)
        s[k] = samples[i * NS + k];
    Shading P;
    P.ka = shading[0]; P.kd = shading[1]; P.ks = shading[2]; P.shininess = shading[3];
    P.whole = P.shininess == floor(P.shininess) && P.shininess <= 64;
    P.exponent = (int)P.shininess;
    P.nlights = 1;
    P.light[0] = (real3)(shading[4], shading[5], shading[6]);
    P.halfway[0] = (real3)(shading[7], shading[8], shading[9]);
    P.grad_floor = shading[10];
    P.scale = (real3)(1);
    int evals = 0, flags = 0, midpoints = 0;
    real left = budget[i];
    OneInterval O;
    bool one = false;
    real4 r;
    if (!post_segment(s, nodes, weights, tf, &P, radius[i], 1, &left, u, c, &O, &one, &r, &midpoints, &evals))
        r = post_gradient(&O, one, c, u, vload16(3 * i, grads), vload16(3 * i + 1, grads), vload16(3 * i + 2, grads),
                          radius[i], nodes, weights, tf, &P, tol, &evals, &flags);
    out[i] = r;
    budget[i] = left;
    stats[i] = (int4)(flags, midpoints, one, evals);
}

/* unpack_pool: every q of slot s of a packed scalar pool (the pool `words`, its `quant`; boxes as field_bspline.h's,
 * w the slot's first coefficient) into out[w ..], rows of up to four by pool_row as the ray tracer reads them; then
 * the rows read again from every x: a q that differs is NaN.  Grid: global (slots). */
__kernel void unpack_pool(__global float *out, __global const uchar *words, __global const Quant *quant,
                          __global const int4 *boxes)
{
    const int s = get_global_id(0);
    const int4 n = boxes[s];
    for (int again = 0; again < 2; again++)
        for (int z = 0; z < n.z; z++)
            for (int y = 0; y < n.y; y++)
                for (int x = 0; x < n.x; x += again ? 1 : 4) {
                    float row[4];
                    const int k = min(4, n.x - x), i = n.w + (z * n.y + y) * n.x + x;
                    pool_row(words, quant[s], n, x, y, z, k, row);
                    for (int r = 0; r < k; r++)
                        out[i + r] = !again || out[i + r] == row[k - 1 - r] ? row[k - 1 - r] : NAN;
                }
}

/* unpack_cells: the j^3 q of cell k (cells[k]: its slot, and its last coefficient within the slot) into
 * out[k j^3 ..] by pool_cell, as the ray tracer's scalar_cell decodes a segment's cell.  Grid: global (cells). */
__kernel void unpack_cells(__global real *out, __global const uchar *words, __global const Quant *quant,
                           __global const int4 *boxes, __global const int2 *cells, const int j)
{
    const int k = get_global_id(0);
    real q[MAX_ORDER * MAX_ORDER * MAX_ORDER];
    const int4 n = boxes[cells[k].x];
    const int last = cells[k].y, row = last / n.x;
    pool_cell(words, quant[cells[k].x], n.x, n.y, (int4)(last - row * n.x, row % n.y, row / n.y, 0), j, q);
    for (int i = 0; i < j * j * j; i++)
        out[(size_t)k * j * j * j + i] = q[i];
}
