/* expand.cl: change of basis from kept wavelet coefficients to fine-level B-spline
 * coefficients (the inverse transform on the whole real line, MATH.md §1 and §4).
 *
 * One launch is one separable synthesis step along one axis for one pair of parts that
 * differ only in that axis' letter: the 'a' part through the lowpass h = p/sqrt2 and the
 * 'd' part through the highpass g = q/sqrt2 (MATH.md §1 "Synthesis step"):
 *
 *     out[L] = sum_t h[t] A[(L - shift_a - t) / 2] + sum_t g[t] D[(L - shift_d - t) / 2]
 *
 * over the taps t with L - shift - t even.  Every array is a box of float4 in absolute
 * index coordinates (the processed axis in child indices, the others in the level's own);
 * a read outside an input's box is zero, so the output box may be larger than the inputs
 * (the ray tracer pads its grids that way).  Host: clwave/finegrid.py. */
#include "clw_common.h"

inline float4 read_box(__global const float4 *a, const int4 start, const int4 shape, const int4 at)
{
    const int4 p = at - start;
    if (p.x < 0 || p.y < 0 || p.z < 0 || p.x >= shape.x || p.y >= shape.y || p.z >= shape.z)
        return (float4)(0.0f);
    return a[((size_t)p.z * shape.y + p.y) * shape.x + p.x];
}

inline float4 filter_part(__global const float4 *a, const int4 start, const int4 shape,
                          __constant const float *taps, const int ntaps, const int shift,
                          int4 at, const int axis, const int child)
{
    float4 acc = (float4)(0.0f);
    const int first = (child - shift) & 1; /* the taps of this output's parity */
    for (int t = first; t < ntaps; t += 2) {
        const int parent = (child - shift - t) >> 1; /* exact: child - shift - t is even */
        if (axis == 0) at.x = parent; else if (axis == 1) at.y = parent; else at.z = parent;
        acc += taps[t] * read_box(a, start, shape, at);
    }
    return acc;
}

/* synth_axis: one synthesis step along `axis` (0 = x, 1 = y, 2 = z; int4 fields x, y, z).
 *
 * Parameters
 *   out          out  box (out_start, out_shape) of float4
 *   a            in   one part with its box, filter (na taps) and shift: the 'a' part with h
 *                     and shift_a, or the 'd' part with g and shift_d
 *   b            in   the other part, likewise; has_b = 0 when it is all zero
 * Grid: global (out_shape.x, out_shape.y, out_shape.z). */
__kernel void synth_axis(__global float4 *out, const int4 out_start, const int4 out_shape, const int axis,
                         __global const float4 *a, const int4 a_start, const int4 a_shape,
                         __constant const float *a_taps, const int na, const int a_shift,
                         __global const float4 *b, const int4 b_start, const int4 b_shape,
                         __constant const float *b_taps, const int nb, const int b_shift, const int has_b)
{
    const int4 idx = (int4)(get_global_id(0), get_global_id(1), get_global_id(2), 0);
    if (idx.x >= out_shape.x || idx.y >= out_shape.y || idx.z >= out_shape.z)
        return;
    const int4 at = out_start + idx;
    const int child = axis == 0 ? at.x : (axis == 1 ? at.y : at.z);
    float4 acc = filter_part(a, a_start, a_shape, a_taps, na, a_shift, at, axis, child);
    if (has_b)
        acc += filter_part(b, b_start, b_shape, b_taps, nb, b_shift, at, axis, child);
    out[((size_t)idx.z * out_shape.y + idx.y) * out_shape.x + idx.x] = acc;
}
