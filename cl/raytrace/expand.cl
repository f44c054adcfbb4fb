/* expand.cl: change of basis from kept wavelet coefficients to fine-level B-spline
 * coefficients (the inverse transform on the whole real line, docs/model.md §1 and §4).
 *
 * One launch is one separable synthesis step along one axis for one pair of parts that
 * differ only in that axis' letter (either may be absent): the 'a' part through the lowpass
 * h = p/sqrt2 and the 'd' part through the highpass g = q/sqrt2 (docs/model.md §1 (the synthesis step)):
 *
 *     out[L] = sum_t h[t] A[(L - shift_a - t) / 2] + sum_t g[t] D[(L - shift_d - t) / 2]
 *
 * over the taps t with L - shift - t even.  Every array is a box of `lanes` (float4, or float for a
 * group of one channel: CLW_LANES = 1, a scalar model's synthesis a quarter of the work) in absolute
 * index coordinates (the processed axis in child indices, the others in the level's own);
 * a read outside an input's box is zero, so the output box may be larger than the inputs
 * (the ray tracer crops them to the boxes its bricks need).  Host: clwave/raytrace/bricks.py. */

#include "common/clw_common.h"

/* Compile-time CLW_AXIS (0 = x, 1 = y, 2 = z), CLW_NH and CLW_NG (the filters' lengths, so that the
 * tap loops unroll), CLW_LANES (4 or 1), and branch-free reads, so that PoCL can vectorise the work-item loop
 * along x. */
#if CLW_LANES == 1
typedef float lanes;
#else
typedef float4 lanes;
#endif
/* one float a coefficient along y or z: a work-item makes four outputs along x (rows are contiguous along x, so
 * the four read one vload4 a tap where they lie in the part's box), each with the same sums as one output alone */
#define CLW_X4 (CLW_LANES == 1 && CLW_AXIS != 0)

inline lanes filter_part(__global const lanes *a, const int4 start, const int4 shape,
                          __constant const float *taps, const int ntaps, const int shift,
                          const int4 at, const int child)
{
    lanes acc = (lanes)(0.0f);
    const int4 p = at - start;
    const bool others_in = CLW_AXIS == 0 ? (p.y >= 0 && p.z >= 0 && p.y < shape.y && p.z < shape.z)
                         : CLW_AXIS == 1 ? (p.x >= 0 && p.z >= 0 && p.x < shape.x && p.z < shape.z)
                                         : (p.x >= 0 && p.y >= 0 && p.x < shape.x && p.y < shape.y);
    const int len = CLW_AXIS == 0 ? shape.x : (CLW_AXIS == 1 ? shape.y : shape.z);
    const int first = (child - shift) & 1; /* the taps of this output's parity */
    const int top = ((child - shift - first) >> 1) - (CLW_AXIS == 0 ? start.x : (CLW_AXIS == 1 ? start.y : start.z));
    const size_t stride = CLW_AXIS == 0 ? 1 : (CLW_AXIS == 1 ? (size_t)shape.x : (size_t)shape.x * shape.y);
    const size_t row = CLW_AXIS == 0 ? ((size_t)p.z * shape.y + p.y) * shape.x
                     : CLW_AXIS == 1 ? (size_t)p.z * shape.y * shape.x + p.x
                                     : (size_t)p.y * shape.x + p.x;
#pragma unroll
    for (int i = 0; 2 * i < ntaps; i++) {
        const int t = first + 2 * i, k = top - i; /* parent index along the axis */
        const bool ok = others_in && t < ntaps && k >= 0 && k < len;
        const lanes v = a[ok ? row + (size_t)k * stride : 0];
        acc += (ok ? taps[min(t, ntaps - 1)] : 0.0f) * v;
    }
    return acc;
}

#if CLW_X4
/* filter_part of the outputs at.x .. at.x + 3 (the others at), lane by lane the same sums */
inline float4 filter_part4(__global const float *a, const int4 start, const int4 shape,
                           __constant const float *taps, const int ntaps, const int shift,
                           const int4 at, const int child)
{
    float4 acc = (float4)(0.0f);
    const int4 p = at - start;
    const int4 px = p.x + (int4)(0, 1, 2, 3);
    const int4 x_in = px >= 0 && px < shape.x;
    const bool all_x = p.x >= 0 && p.x + 3 < shape.x;
    const bool others_in = CLW_AXIS == 1 ? (p.z >= 0 && p.z < shape.z) : (p.y >= 0 && p.y < shape.y);
    const int len = CLW_AXIS == 1 ? shape.y : shape.z;
    const int first = (child - shift) & 1; /* the taps of this output's parity */
    const int top = ((child - shift - first) >> 1) - (CLW_AXIS == 1 ? start.y : start.z);
    const long stride = CLW_AXIS == 1 ? (long)shape.x : (long)shape.x * shape.y;
    const long row = CLW_AXIS == 1 ? (long)p.z * shape.y * shape.x + p.x : (long)p.y * shape.x + p.x;
#pragma unroll
    for (int i = 0; 2 * i < ntaps; i++) {
        const int t = first + 2 * i, k = top - i; /* parent index along the axis */
        const bool ok = others_in && t < ntaps && k >= 0 && k < len;
        const long at_k = row + k * stride;
        float4 v;
        if (ok && all_x)
            v = vload4(0, a + at_k);
        else
            v = (float4)(a[ok && x_in.x ? at_k : 0], a[ok && x_in.y ? at_k + 1 : 0], a[ok && x_in.z ? at_k + 2 : 0],
                         a[ok && x_in.w ? at_k + 3 : 0]);
        const float tap = taps[min(t, ntaps - 1)];
        acc += select((float4)(0.0f), (float4)(tap), x_in & (int4)(ok ? -1 : 0)) * v;
    }
    return acc;
}
#endif

/* synth_axis: one synthesis step along CLW_AXIS (int4 fields x, y, z).
 *
 * Parameters
 *   out          out  box (out_start, out_shape) of lanes
 *   a            in   the 'a' part with its box, through h (CLW_NH taps) with shift_a; has_a = 0: none
 *   d            in   the 'd' part with its box, through g (CLW_NG taps) with shift_d; has_d = 0: none
 * Grid: global (out_shape.x, out_shape.y, out_shape.z), CLW_X4: ((out_shape.x + 3) / 4, out_shape.y, out_shape.z). */
__kernel void synth_axis(__global lanes *out, const int4 out_start, const int4 out_shape,
                         __global const lanes *a, const int4 a_start, const int4 a_shape,
                         __constant const float *h, const int a_shift, const int has_a,
                         __global const lanes *d, const int4 d_start, const int4 d_shape,
                         __constant const float *g, const int d_shift, const int has_d)
{
#if CLW_X4
    const int4 idx = (int4)(4 * get_global_id(0), get_global_id(1), get_global_id(2), 0);
#else
    const int4 idx = (int4)(get_global_id(0), get_global_id(1), get_global_id(2), 0);
#endif
    if (idx.x >= out_shape.x || idx.y >= out_shape.y || idx.z >= out_shape.z)
        return;
    const int4 at = out_start + idx;
    const int child = CLW_AXIS == 0 ? at.x : (CLW_AXIS == 1 ? at.y : at.z);
#if CLW_X4
    float4 acc = (float4)(0.0f);
    if (has_a)
        acc = filter_part4(a, a_start, a_shape, h, CLW_NH, a_shift, at, child);
    if (has_d)
        acc += filter_part4(d, d_start, d_shape, g, CLW_NG, d_shift, at, child);
    __global float *o = out + ((size_t)idx.z * out_shape.y + idx.y) * out_shape.x + idx.x;
    if (idx.x + 3 < out_shape.x) {
        vstore4(acc, 0, o);
    } else {
        const float v[4] = {acc.x, acc.y, acc.z, acc.w};
        for (int l = 0; l < out_shape.x - idx.x; l++)
            o[l] = v[l];
    }
#else
    lanes acc = (lanes)(0.0f);
    if (has_a)
        acc = filter_part(a, a_start, a_shape, h, CLW_NH, a_shift, at, child);
    if (has_d)
        acc += filter_part(d, d_start, d_shape, g, CLW_NG, d_shift, at, child);
    out[((size_t)idx.z * out_shape.y + idx.y) * out_shape.x + idx.x] = acc;
#endif
}
