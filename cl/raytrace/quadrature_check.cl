/* quadrature_check.cl: the normal's resolution rule of quadrature.h (normal_turns, series_turns) on given gradients,
 * for its test against the NumPy oracle (tests/test_normal_turns.py).  Build with CLW_SAMPLES, CLW_GROUPS,
 * CLW_ORDERS, CLW_MAX_DEPTH and CLW_SHADE.
 *   turns    (n,) int: the rule's bits (bit 0: the first panel, bit 1: the second)
 *   shading  (n, 4): the scale (fine units per world unit, x, y, z) and the flat gradients' floor
 * lane_turns: lanes (n, 3, 16): alpha's fine gradient per axis at lanes 0..8 (lane p - 1: p = 1..8, lane 8: p = 0)
 * span_turns: series (n, NG, 3): the gradient's Chebyshev series; spans (n,) real2 (l, r); counts (n,): points l + (r -
 * l) p / count, count 4 (one panel) or 8 (two).  Grid: global (n). */
#include "raytrace/types.h"
#include "raytrace/quadrature.h"

inline Shading rule(__global const real *shading)
{
    Shading P;
    P.scale = (real3)(shading[0], shading[1], shading[2]);
    P.grad_floor = shading[3];
    return P;
}

__kernel void lane_turns(__global int *turns, __global const real *lanes, __global const real *shading, const int n)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const Shading P = rule(shading + 4 * i);
    turns[i] = normal_turns(vload16(3 * i, lanes), vload16(3 * i + 1, lanes), vload16(3 * i + 2, lanes), &P);
}

__kernel void span_turns(__global int *turns, __global const real *series, __global const real2 *spans,
                         __global const int *counts, __global const real *shading, const int n)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const Shading P = rule(shading + 4 * i);
    real3 g[NG];
    for (int m = 0; m < NG; m++)
        g[m] = vload3(i * NG + m, series);
    turns[i] = series_turns(g, &P, spans[i].x, spans[i].y, counts[i]);
}
