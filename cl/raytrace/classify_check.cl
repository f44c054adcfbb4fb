/* classify_check.cl: classified_segment (classify.h) on given segments, for its test against an independent
 * quadrature (tests/test_classify.py).  Unshaded; build with CLW_POST, CLW_SAMPLES, CLW_GROUPS, CLW_ORDERS,
 * CLW_MAX_DEPTH.
 *   out      (n,) real4: int q e^{-A} dxi (rgb) and int alpha dxi over xi in [-1, 1]
 *   samples  (n, CLW_SAMPLES) the scalar at the sample points (lane order of the ray tracer's fq)
 *   radius   (n,) half the segment length; nodes, weights, tf as in raytrace.cl; tol on the emission (xi units)
 *   flags    (n,) the segment's flags (bit 1: a span or panel at its depth limit)
 * Grid: global (n). */
#include "raytrace/types.h"
#include "raytrace/classify.h"

__kernel void classify_segments(__global real4 *out, __global const real *samples, __global const real *radius,
                                __constant const real *nodes, __constant const real *weights,
                                __global const real4 *tf, const real tol, __global int *flags, const int n)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    real s[NS], flat[16];
    real3 g[9];
    for (int k = 0; k < NS; k++)
        s[k] = samples[i * NS + k];
    for (int m = 0; m < 9; m++)
        g[m] = (real3)(0);
    for (int k = 0; k < 16; k++)
        flat[k] = 0;
    Shading P;
    P.nlights = 0;
    int evals = 0, f = 0;
    real u[NS], c[NS];
    out[i] = segment_scalar(s, nodes, tf, u, c)
                 ? classified_segment(c, u, flat, flat, flat, g, radius[i], nodes, weights, tf, &P, tol, &evals, &f)
                 : (real4)(0);
    flags[i] = f;
}
