/* footprint.cl: half-spectra of footprint textures by Fourier projection slicing (paper §4.3,
 * eq. 32; docs/splatting.md §1), many textures in one launch.  The host (clwave/splat/textures.py) inverts
 * each with a real 2-D FFT; its NumPy twin is clwave.splat.spectral._Axis.
 *
 * Texture t's spectrum is the slice F(U u + V v) at U = c du (column c = 0 .. nu/2) and
 * V = kv dv (row r in numpy.fft.fftfreq order: kv = r in the first half, r - nv after).  Per world axis a, with
 * x_a = rate_a.x c + rate_a.y kv (x = w/2 for phi, w/4 for psi),
 *     phi: (sin x / x)^J,      psi: (sin^2 x / x)^J P(sin^2 x)  (M < J moments: (sin x / x)^J sin^M x P(sin^2 x),
 *     the last two factors given as Chebyshev coefficients in sin x),
 * and the texture's value is phase * prod_a (complex: the centred factors are real, or
 * imaginary for odd-order psi; psi's 1/2, det(D) 2^(3m/2) and the inverse FFT's scale are in
 * phase).  An axis parallel to n is given as phi with rate (0, 0): a factor of 1.
 *
 * The host sets CLW_ORDER (J), CLW_TERMS (P's coefficients) and CLW_MOMENTS (psi's vanishing moments M).  Each work-item computes 16
 * columns as float16: PoCL vectorises the sines that way, not across work-items.
 *
 * Perspective views (clwave/splat/perspective.py) set CLW_QUASI: the texture is stored as a quasi-interpolant, the
 * samples less 1/16 of their second differences along rows and columns, which is the spectrum times
 * 1 + (sin^2(pi c / nu) + sin^2(pi kv / nv)) / 4 (docs/splatting.md §8).  Orthographic views do not. */
#include "common/clw_common.h"

inline float16 power(const float16 x)
{
    float16 p = x;
    for (int k = 1; k < CLW_ORDER; k++)
        p *= x;
    return p;
}

inline float16 axis_factor(const float16 x, const int psi, __constant const float *poly)
{
    const float16 s = sin(x);
    /* sin(x) / x to float rounding for |x| < 1e-3 (the next term is x^4 / 120) */
    const float16 sinc = select(s / x, 1.0f - x * x / 6.0f, fabs(x) < 1e-3f);
    if (!psi)
        return power(sinc);
#if CLW_MOMENTS == CLW_ORDER
    const float16 s2 = s * s;
    float16 p = (float16)(poly[CLW_TERMS - 1]);
    for (int r = CLW_TERMS - 2; r >= 0; r--)
        p = p * s2 + poly[r];
    return power(sinc * s) * p;
#else /* poly: s^M P(s^2) as Chebyshev coefficients, summed by Clenshaw (its power form loses 3e-4 in float) */
    float16 b1 = (float16)(0.0f), b2 = (float16)(0.0f);
    for (int r = CLW_TERMS - 1; r >= 1; r--) {
        const float16 b0 = 2.0f * s * b1 - b2 + poly[r];
        b2 = b1;
        b1 = b0;
    }
    return power(sinc) * (s * b1 - b2 + poly[0]);
#endif
}

/* footprint_spectra
 *
 * Parameters
 *   group_tex  in  (groups,) int: the texture of each work-group
 *   tex_size   in  (T,) int4: (first work-item, rows nv, blocks of 16 columns per row, psi bits:
 *                  bit a for axis a, and the columns nu from bit 3 on)
 *   tex_rate   in  (T,) float8: (rate, rate, rate, phase) as 4 float2: the rates of the axes not
 *                  parallel to n, in world order, then (0, 0) for each such axis
 *   poly       in  (CLW_TERMS,) float: P's coefficients, lowest power first
 *   out        out float2: texture t's (rows, 16 x blocks) spectrum from 16 x its first work-item
 *                  (columns past nu/2 are padding)
 * Grid: each texture's rows x blocks work-items rounded up to whole work-groups, one texture
 * per group; the local size is the one group_tex was made for (clwave.splat.spectral.SPECTRUM_GROUP). */
__kernel void footprint_spectra(__global const int *group_tex, __global const int4 *tex_size,
                                __global const float8 *tex_rate, __constant const float *poly,
                                __global float *out)
{
    const int t = group_tex[get_group_id(0)];
    const int4 size = tex_size[t];
    const int i = (int)get_global_id(0) - size.x;
    if (i >= size.y * size.z)
        return;
    const int row = i / size.z;
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const float16 c = lane + (float)(16 * (i - row * size.z));
    const float kv = (float)(row < (size.y + 1) / 2 ? row : row - size.y);  /* numpy.fft.fftfreq */
    const float8 r = tex_rate[t];
    const float16 value = axis_factor(r.s0 * c + r.s1 * kv, size.w & 1, poly)
                        * axis_factor(r.s2 * c + r.s3 * kv, (size.w >> 1) & 1, poly)
                        * axis_factor(r.s4 * c + r.s5 * kv, (size.w >> 2) & 1, poly);
#ifdef CLW_QUASI
    const float16 su = sinpi(c / (float)(size.w >> 3));
    const float sv = sinpi(kv / (float)size.y);
    const float16 quasi = 1.0f + (su * su + sv * sv) * 0.25f;
    const float16 re = value * r.s6 * quasi, im = value * r.s7 * quasi;
#else
    const float16 re = value * r.s6, im = value * r.s7;
#endif
    const uint16 low = (uint16)(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
    vstore16(shuffle2(re, im, low), 0, out + 32 * get_global_id(0));
    vstore16(shuffle2(re, im, low + 8u), 0, out + 32 * get_global_id(0) + 16);
}
