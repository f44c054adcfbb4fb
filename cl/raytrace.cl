/* raytrace.cl: the emission-absorption integral per pixel (paper §3, eq. 5 and 17, MATH.md §7).
 *
 * One work-item per ray.  The ray is cut at every knot plane of every channel group's
 * fine B-spline lattice (clwave/finegrid.py); inside a segment the field (q_R, q_G, q_B, alpha)
 * and the gradient of alpha are polynomials in t, of degree <= 3(j - 1).  They are sampled at
 * CLW_SAMPLES points xi of the segment [-1, 1]: the 9 points xi = -1 + p/4 of Simpson's first 2
 * panels and their halves, plus xi = 15/16 when the degree is 9 (cubic), so that
 *   - A(a, t) = int_a^t alpha is exact (integration weights of the interpolating polynomial at
 *     the 9 points; the antiderivative of its Chebyshev series, made only when a panel must be
 *     halved further),
 *   - int_a^b q e^{-A} comes from adaptive Simpson on that polynomial (>= 2 initial panels,
 *     accept |S2 - S1| <= 15 tol, return S2 + (S2 - S1)/15), with the shaded q of eq. 4,
 *   - in X-ray mode (CLW_XRAY) int_a^b f is exact (the same weights over the whole segment).
 * Lanes 0..7 of a sample vector hold p = 1..8, lane 8 p = 0 and lane 9 the extra point.  Where
 * the field is C^1 across knot planes (CLW_JOIN: every order >= 3), a segment that starts where
 * the last evaluated one ended takes p = 0 (the field, and the shaded emission and the gradient of
 * alpha when that segment was shaded point by point) from the last one's p = 8: alpha's gradient
 * is then needed at 8 points, one real8.
 * The budget tol per output value is split: half for the quadrature, spread along the ray in
 * proportion to segment length and relaxed by 1/T (MATH.md §7); a quarter for early ray
 * termination; a quarter for empty space.  With shading, three quarters of the quadrature's half
 * go to segments shaded at the midpoint of their shading range (the quadrature's own errors are
 * far below its share at the usual tolerances): shading makes q (ka + kd D) + ks alpha S
 * of q with D, S in [0, nlights], so (ka + kd n/2) q + (ks n/2) alpha errs by at most the half
 * width (kd q + ks alpha) n/2; a segment whose unshaded integrals (Simpson's 4 panels, |S4 - S2|
 * added as their error) make that fit in what is left of that share needs no gradient, which is
 * a third of the work.  Termination and skipping use the blocks of CLW_BLOCK^3 fine cells with a
 * bound b on |field| (cl/blocks.cl) and R(t), the integral of b along the rest of the ray beyond t
 * (summed block by block before the march): the rest can add at most T R gain of emission and
 * T min(1, R) of opacity, so the ray stops once T max(min(1, R), R gain) <= tol/4.  A block is
 * skipped while what it could change stays within what is left of the empty-space quarter: over a
 * length l at transmittance T it could add T b l gain of emission, T b l of opacity, and by its
 * optical depth b l dim the rest of the ray by at most T b l R gain.  X-ray mode spends half of tol
 * on skipping (its segment integrals are exact).
 *
 * Compile-time: CLW_GROUPS grids with orders CLW_ORDERS; CLW_ALPHA the grid holding alpha;
 * CLW_SAMPLES samples per segment (9 or 10); CLW_JOIN when every order is >= 3; CLW_LATTICE 1 or
 * 0.5 (orders of both parities); CLW_SHADE for Phong shading; CLW_XRAY for line integrals;
 * CLW_DOUBLE for a float64 build. */
#include "clw_common.h"

#ifdef CLW_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
typedef double8 real8;
typedef double16 real16;
#define REAL_EPSILON DBL_EPSILON
#define to_real4(v) convert_double4(v)
#define to_real3(v) convert_double3(v)
#define convert_real3 convert_double3
#define fast_exp exp
#define fast_exp2 exp2
#define fast_log2 log2
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
typedef float8 real8;
typedef float16 real16;
#define REAL_EPSILON FLT_EPSILON
#define to_real4(v) (v)
#define to_real3(v) (v)
#define convert_real3 convert_float3
#define fast_exp native_exp
#define fast_exp2 native_exp2
#define fast_log2 native_log2
#endif

#define NS CLW_SAMPLES
#define P0 8 /* the lane of xi = -1 */
#ifdef CLW_JOIN
#define JOIN 1
#else
#define JOIN 0
#endif

/* The samples of a segment in the lanes of one vector (lanes NS.. repeat lane 0, unused) */
typedef real16 realv;

constant int ORDER[CLW_GROUPS] = {CLW_ORDERS};

#ifndef CLW_WAVELET
/* ---- B-spline path: the fine grids the kept coefficients expand to (clwave/finegrid.py) ---- */
#define FIELD_PARAMS __global const float4 *coef, __constant const int4 *start, __constant const int4 *shape, \
                     __constant const int *offset
typedef struct {
    __global const float4 *coef;
    __constant const int4 *start, *shape;
    __constant const int *offset;
} Field;
#define FIELD_INIT {coef, start, shape, offset}
typedef int Active; /* no per-ray state */
inline void active_init(Active *A, const Field G, const size_t pix, const real3 X0, const real3 D) { *A = 0; }
inline int active_flags(const Active *A) { return 0; }

/* w[r] = N_j(u + r) (BSPLINE_WEIGHTS) and dw[r] = N_j'(u + r) (BSPLINE_DERIVATIVES), r = 0..j-1:
 * the weight of coefficient c - r in cell c at u = x - c (MATH.md §1), per lane of TYPE.
 * Polynomials, so they hold a little outside [0, 1) too.  Products, not divisions by constants:
 * PoCL keeps those as divisions. */
#define BSPLINE_WEIGHTS(TYPE, NAME)                                                               \
    inline void NAME(const int j, const TYPE u, TYPE *w)                                          \
    {                                                                                             \
        const TYPE s = 1 - u;                                                                     \
        const real one_half = (real)0.5, sixth = (real)1 / 6;                                     \
        if (j == 1) {                                                                             \
            w[0] = 1;                                                                             \
        } else if (j == 2) {                                                                      \
            w[0] = u; w[1] = s;                                                                   \
        } else if (j == 3) {                                                                      \
            w[0] = u * u * one_half; w[1] = (-2 * u * u + 2 * u + 1) * one_half; w[2] = s * s * one_half; \
        } else {                                                                                  \
            w[0] = u * u * u * sixth; w[1] = ((-3 * u + 3) * u * u + 3 * u + 1) * sixth;          \
            w[2] = ((3 * u - 6) * u * u + 4) * sixth; w[3] = s * s * s * sixth;                   \
        }                                                                                         \
    }
#define BSPLINE_DERIVATIVES(TYPE, NAME)                                                           \
    inline void NAME(const int j, const TYPE u, TYPE *dw)                                         \
    {                                                                                             \
        const real one_half = (real)0.5;                                                          \
        if (j == 2) {                                                                             \
            dw[0] = 1; dw[1] = -1;                                                                \
        } else if (j == 3) {                                                                      \
            dw[0] = u; dw[1] = 1 - 2 * u; dw[2] = u - 1;                                          \
        } else if (j == 4) {                                                                      \
            dw[0] = u * u * one_half; dw[1] = (-3 * u * u + 2 * u + 1) * one_half;                \
            dw[2] = (3 * u - 4) * u * one_half; dw[3] = -(1 - u) * (1 - u) * one_half;            \
        }                                                                                         \
    }
BSPLINE_WEIGHTS(real8, bspline_weights8)
BSPLINE_WEIGHTS(real4, bspline_weights4)
BSPLINE_DERIVATIVES(real8, bspline_derivatives8)
BSPLINE_DERIVATIVES(real4, bspline_derivatives4)

/* One group's part of the field at sample k: the j^3 coefficients ending at `corner` (the
 * segment's cell), summed separably (along x per (y, z) row, then along y per z plane, then
 * along z) with sample k's weights w?[r * 16 + k]; rows are `sy` apart, planes `sz`.  Always
 * inlined with a literal order j, so the loops unroll. */
__attribute__((always_inline)) inline real4 group_field(__global const float4 *corner, const int sy, const int sz,
                                                        const int j, const real *wx, const real *wy, const real *wz,
                                                        const int k)
{
    real4 v = (real4)(0);
#pragma unroll
    for (int rz = 0; rz < j; rz++) {
        real4 plane = (real4)(0);
#pragma unroll
        for (int ry = 0; ry < j; ry++) {
            __global const float4 *row = corner - rz * sz - ry * sy;
            real4 line = (real4)(0);
#pragma unroll
            for (int rx = 0; rx < j; rx++)
                line = fma(to_real4(row[-rx]), (real4)(wx[rx * 16 + k]), line);
            plane = fma(line, (real4)(wy[ry * 16 + k]), plane);
        }
        v = fma(plane, (real4)(wz[rz * 16 + k]), v);
    }
    return v;
}

/* The alpha group's part of alpha's fine gradient at all lanes of TYPE at once: the same
 * separable sum as group_field on the alpha channel, with the derivative weights d? */
#define GROUP_GRADIENT(TYPE, NAME)                                                                        \
    __attribute__((always_inline)) inline void NAME(__global const float4 *corner, const int sy, const int sz, \
                                                    const int j, const TYPE *wx, const TYPE *wy, const TYPE *wz, \
                                                    const TYPE *dx, const TYPE *dy, const TYPE *dz, TYPE *gx,   \
                                                    TYPE *gy, TYPE *gz)                                         \
    {                                                                                                     \
        _Pragma("unroll") for (int rz = 0; rz < j; rz++) {                                                \
            TYPE plane = 0, plane_dx = 0, plane_dy = 0;                                                   \
            _Pragma("unroll") for (int ry = 0; ry < j; ry++) {                                            \
                __global const float4 *row = corner - rz * sz - ry * sy;                                  \
                TYPE line = 0, line_dx = 0;                                                               \
                _Pragma("unroll") for (int rx = 0; rx < j; rx++) {                                        \
                    const TYPE a = (TYPE)(row[-rx].w);                                                    \
                    line = fma(a, wx[rx], line);                                                          \
                    line_dx = fma(a, dx[rx], line_dx);                                                    \
                }                                                                                         \
                plane = fma(line, wy[ry], plane);                                                         \
                plane_dx = fma(line_dx, wy[ry], plane_dx);                                                \
                plane_dy = fma(line, dy[ry], plane_dy);                                                   \
            }                                                                                             \
            *gx = fma(plane_dx, wz[rz], *gx);                                                             \
            *gy = fma(plane_dy, wz[rz], *gy);                                                             \
            *gz = fma(plane, dz[rz], *gz);                                                                \
        }                                                                                                 \
    }
GROUP_GRADIENT(real8, group_gradient8)
GROUP_GRADIENT(real4, group_gradient4)

/* What a grid's part of a segment needs besides its samples: the cell's last coefficient, and per
 * axis the position u in the cell and the B-spline weights w at lanes 0..7 (real8) and 8..11
 * (real4: the lanes past NS are unused) */
typedef struct {
    __global const float4 *corner;
    int sy, sz;
    real8 u[3], w[3][4];
    real4 u4[3], w4[3][4];
} Basis;

/* Grid g's part of the segment at the sample points xm + radius xi_k D, sample k in lane k.  Every
 * sample comes from the cells holding the midpoint xm, so from the same polynomial. */
inline void segment_basis(const Field G, const int g, const real3 xm, const real radius, const real3 D,
                          __constant const real *nodes, Basis *B)
{
    real lane_xi[12];
    for (int k = 0; k < 12; k++)
        lane_xi[k] = nodes[k < NS ? k : 0];
    const real8 xi = vload8(0, lane_xi);
    const real4 xi4 = vload4(2, lane_xi);
    const int j = ORDER[g];
    const real3 x = xm + (real)(j - ORDER[0]) / 2; /* grid g's lattice (MATH.md §7) */
    const int4 s = G.shape[g], lo = G.start[g];
    const int4 c = (int4)(clamp(convert_int4((real4)(floor(x), 0)).xyz, lo.xyz + j - 1, lo.xyz + s.xyz - 1), 0);
    const int4 p = c - lo;
    const real3 u = x - convert_real3(c.xyz), step = radius * D; /* x - cell at xi = 0, and per unit xi */
    const real ua[3] = {u.x, u.y, u.z}, sa[3] = {step.x, step.y, step.z};
    for (int a = 0; a < 3; a++) {
        B->u[a] = ua[a] + sa[a] * xi;
        B->u4[a] = ua[a] + sa[a] * xi4;
        bspline_weights8(j, B->u[a], B->w[a]);
        bspline_weights4(j, B->u4[a], B->w4[a]);
    }
    B->sy = s.x;
    B->sz = s.x * s.y;
    B->corner = G.coef + G.offset[g] + ((size_t)p.z * s.y + p.y) * s.x + p.x;
}

/* The field at the segment's sample points (lane P0 only when `fresh`: else it is the last
 * segment's end), and each grid's Basis for the gradient */
inline void sample_segment(const Field G, Active *A, const real t_mid, const real3 xm, const real radius,
                           const real3 D, __constant const real *nodes, const bool fresh, real4 *fq,
                           Basis *basis)
{
    for (int k = 0; k < NS; k++)
        fq[k] = (real4)(0);
    for (int g = 0; g < CLW_GROUPS; g++) {
        Basis *B = &basis[g];
        segment_basis(G, g, xm, radius, D, nodes, B);
        const int j = ORDER[g];
        real lw[3][64]; /* the weights per sample and axis, for the field's float4 sums */
        for (int a = 0; a < 3; a++)
            for (int r = 0; r < j; r++) {
                vstore8(B->w[a][r], 2 * r, lw[a]);
                vstore4(B->w4[a][r], 4 * r + 2, lw[a]);
            }
        for (int k = 0; k < NS; k++) {
            if (k == P0 && !fresh)
                continue;
            switch (j) {
            case 1: fq[k] += group_field(B->corner, B->sy, B->sz, 1, lw[0], lw[1], lw[2], k); break;
            case 2: fq[k] += group_field(B->corner, B->sy, B->sz, 2, lw[0], lw[1], lw[2], k); break;
            case 3: fq[k] += group_field(B->corner, B->sy, B->sz, 3, lw[0], lw[1], lw[2], k); break;
            default: fq[k] += group_field(B->corner, B->sy, B->sz, 4, lw[0], lw[1], lw[2], k); break;
            }
        }
    }
}

/* alpha's fine gradient in the lanes of (gx, gy, gz), only for segments shaded point by point:
 * lanes 0..8, or lanes 0..7 (one real8) when lane P0 comes from the last segment */
#define GRADIENT_LANES(W, WIDTH, U, OUT)                                                                  \
    {                                                                                                     \
        real##WIDTH d[3][4], hx = 0, hy = 0, hz = 0;                                                      \
        for (int a = 0; a < 3; a++)                                                                       \
            bspline_derivatives##WIDTH(j, B->U[a], d[a]);                                                 \
        __global const float4 *c = B->corner;                                                             \
        const real##WIDTH *wx = B->W[0], *wy = B->W[1], *wz = B->W[2];                                   \
        switch (j) { /* order 1 has no gradient: shading is off for Haar alpha */                         \
        case 2: group_gradient##WIDTH(c, B->sy, B->sz, 2, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break; \
        case 3: group_gradient##WIDTH(c, B->sy, B->sz, 3, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break; \
        case 4: group_gradient##WIDTH(c, B->sy, B->sz, 4, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break; \
        }                                                                                                 \
        gx->OUT = hx; gy->OUT = hy; gz->OUT = hz;                                                         \
    }
inline void sample_gradient(const Basis *basis, const bool all, realv *gx, realv *gy, realv *gz)
{
    const Basis *B = &basis[CLW_ALPHA];
    const int j = ORDER[CLW_ALPHA];
    *gx = 0; *gy = 0; *gz = 0;
    GRADIENT_LANES(w, 8, u, lo)
    if (all)
        GRADIENT_LANES(w4, 4, u4, s89ab)
}
#else
#include "raytrace_wavelet.h"
#endif

/* Clenshaw sums of Chebyshev series sum_m a[m] T_m(x), m < n */
#define CLENSHAW(TYPE, NAME)                                          \
    inline TYPE NAME(const TYPE *a, const int n, const real x)        \
    {                                                                 \
        TYPE b1 = (TYPE)(0), b2 = (TYPE)(0);                          \
        for (int m = n - 1; m >= 1; m--) {                            \
            const TYPE b0 = 2 * x * b1 - b2 + a[m];                   \
            b2 = b1;                                                  \
            b1 = b0;                                                  \
        }                                                             \
        return x * b1 - b2 + a[0];                                    \
    }
CLENSHAW(real, cheb1)
CLENSHAW(real3, cheb3)
CLENSHAW(real4, cheb4)

typedef struct {
    real4 fq[NS];    /* the field at the sample points, alpha clamped to >= 0 */
    realv gx, gy, gz; /* the gradient of alpha there (fine units), lanes 0..8 */
    real radius;     /* half the segment length in world units */
    bool series;     /* q, g, A below are made (only panels finer than quarters need them) */
    real4 q[NS];     /* field series (q_R, q_G, q_B, alpha) in xi in [-1, 1] */
    real3 g[9];      /* gradient-of-alpha series (fine units), of degree <= 8 */
    real A[NS + 1];  /* antiderivative of alpha in xi, zero at xi = -1 (times radius = optical depth) */
} Segment;

/* the Chebyshev series of the segment's samples (nodes: the points, then the field's and the
 * gradient's sample-to-series matrices), and the antiderivative of alpha's */
inline void segment_series(Segment *S, __constant const real *nodes)
{
    for (int m = 0; m < NS; m++) {
        real4 aq = (real4)(0);
        for (int k = 0; k < NS; k++)
            aq += S->fq[k] * nodes[NS + m * NS + k];
        S->q[m] = aq;
    }
#ifdef CLW_SHADE /* only shading reads the gradient series */
    real gx[16], gy[16], gz[16];
    vstore16(S->gx, 0, gx);
    vstore16(S->gy, 0, gy);
    vstore16(S->gz, 0, gz);
    for (int m = 0; m < 9; m++) {
        real3 ag = (real3)(0);
        for (int k = 0; k < 9; k++)
            ag += (real3)(gx[k], gy[k], gz[k]) * nodes[NS + NS * NS + m * 9 + k];
        S->g[m] = ag;
    }
#endif
    /* C_k = (a'_{k-1} - a_{k+1}) / 2k, a'_0 = 2 a_0, and C_0 so that A(-1) = 0 */
    real c0 = 0, sign = -1;
    for (int k = 1; k <= NS; k++) {
        const real prev = S->q[k - 1].w * (k == 1 ? 2 : 1);
        const real next = k + 1 < NS ? S->q[k + 1].w : 0;
        S->A[k] = (prev - next) / (2 * k);
        c0 -= sign * S->A[k];
        sign = -sign;
    }
    S->A[0] = c0;
    S->series = true;
}

typedef struct {
    real ka, kd, ks, shininess;
    real grad_floor; /* world gradients of alpha this short are flat: no normal, ambient light only */
    int nlights;
    real3 light[8], halfway[8];
    real3 scale;     /* fine units per world unit, per axis: world gradient = fine gradient * scale */
} Shading;

#ifdef CLW_SHADE
#define SHADING 1
#else
#define SHADING 0
#endif
/* The shaded emission of eq. 4, (r, g, b) in place, from the field (r, g, b, a) and the fine
 * gradient of alpha (gx, gy, gz): one point (TYPE real) or eight at once (real8; the comparisons
 * and ?: then act per lane, so the same text serves both). */
#define SHADE(TYPE, NAME)                                                                            \
    inline void NAME(TYPE *r, TYPE *g, TYPE *b, const TYPE a, const TYPE gx, const TYPE gy, const TYPE gz, \
                     const Shading *P)                                                               \
    {                                                                                                \
        *r = fmax(*r, (TYPE)(0)); *g = fmax(*g, (TYPE)(0)); *b = fmax(*b, (TYPE)(0));                \
        if (!SHADING)                                                                                \
            return;                                                                                  \
        const TYPE wx = gx * P->scale.x, wy = gy * P->scale.y, wz = gz * P->scale.z;                 \
        const TYPE len = sqrt(wx * wx + wy * wy + wz * wz);                                          \
        /* outward: alpha decreases along n (MATH.md §4); flat below grad_floor */                   \
        const TYPE flat = len > P->grad_floor ? (TYPE)(0) : (TYPE)(1);                               \
        const TYPE inv = -1 / (len + flat);                                                          \
        const TYPE nx = wx * inv, ny = wy * inv, nz = wz * inv;                                      \
        TYPE diffuse = (TYPE)(0), specular = (TYPE)(0);                                              \
        for (int i = 0; i < P->nlights; i++) {                                                       \
            diffuse += fmax(nx * P->light[i].x + ny * P->light[i].y + nz * P->light[i].z, (TYPE)(0)); \
            /* max(c, 0)^shininess as exp2(shininess log2 c): PoCL's pow goes through           */   \
            /* extended-precision logarithms and took a quarter of the render time             */   \
            const TYPE c = nx * P->halfway[i].x + ny * P->halfway[i].y + nz * P->halfway[i].z;       \
            specular += c > 0 ? fast_exp2(P->shininess * fast_log2(c)) : (TYPE)(P->shininess == 0);  \
        }                                                                                            \
        diffuse = flat > 0 ? (TYPE)(0) : diffuse;                                                    \
        specular = flat > 0 ? (TYPE)(0) : P->ks * fmax(a, (TYPE)(0)) * specular;                     \
        const TYPE lit = P->ka + P->kd * diffuse;                                                    \
        *r = *r * lit + specular; *g = *g * lit + specular; *b = *b * lit + specular;                \
    }
SHADE(real, shade)
SHADE(real8, shade8)

/* q e^{-A} at xi from the series: the shaded emission attenuated inside the segment */
inline real3 integrand(const Segment *S, const Shading *P, const real xi)
{
    const real4 f = cheb4(S->q, NS, xi);
    const real3 g = cheb3(S->g, 9, xi);
    real r = f.x, gr = f.y, b = f.z;
    shade(&r, &gr, &b, f.w, g.x, g.y, g.z, P);
    return (real3)(r, gr, b) * fast_exp(-S->radius * cheb1(S->A, NS + 1, xi));
}

typedef struct {
    real l, r, tol;
    real3 fl, fm, fr;
    int depth; /* halvings from the whole segment */
} Panel;

/* int_{-1}^{1} q e^{-A} dxi by adaptive Simpson from 2 panels; counts evaluations, flags depth.
 * f9 holds the integrand at xi = -1 + p/4, p = 0..8: the 2 panels and their halves.
 * Depth first, right half pushed first: the stack holds at most one panel per depth. */
inline real3 simpson(Segment *S, const Shading *P, const real3 *f9, __constant const real *nodes, const real tol,
                     int *evals, int *flags)
{
    Panel stack[CLW_MAX_DEPTH + 1];
    int top = 0;
    *evals += 9;
    stack[0].l = 0; stack[0].r = 1; stack[0].fl = f9[4]; stack[0].fm = f9[6]; stack[0].fr = f9[8];
    stack[1].l = -1; stack[1].r = 0; stack[1].fl = f9[0]; stack[1].fm = f9[2]; stack[1].fr = f9[4];
    stack[0].tol = stack[1].tol = tol / 2;
    stack[0].depth = stack[1].depth = 1;
    top = 2;
    real3 total = (real3)(0);
    while (top > 0) {
        const Panel p = stack[--top];
        const real m = (p.l + p.r) / 2, w = p.r - p.l;
        real3 flm, fmr;
        if (p.depth == 1) {
            flm = f9[p.l < 0 ? 1 : 5];
            fmr = f9[p.l < 0 ? 3 : 7];
        } else {
            if (!S->series)
                segment_series(S, nodes);
            flm = integrand(S, P, (p.l + m) / 2);
            fmr = integrand(S, P, (m + p.r) / 2);
            *evals += 2;
        }
        const real3 s1 = w / 6 * (p.fl + 4 * p.fm + p.fr);
        const real3 s2 = w / 12 * (p.fl + 4 * flm + 2 * p.fm + 4 * fmr + p.fr);
        const real3 d = fabs(s2 - s1);
        const real err = fmax(d.x, fmax(d.y, d.z));
        /* below the rounding floor of the arithmetic, halving the panel cannot help */
        const real floor_err = 16 * REAL_EPSILON * fmax(fabs(s2.x), fmax(fabs(s2.y), fabs(s2.z)));
        if (err <= fmax(15 * p.tol, floor_err) || p.depth >= CLW_MAX_DEPTH) {
            if (err > fmax(15 * p.tol, floor_err))
                *flags |= 2;
            total += s2 + (s2 - s1) / 15;
        } else {
            Panel *right = &stack[top++], *left = &stack[top++];
            right->l = m; right->r = p.r; right->fl = p.fm; right->fm = fmr; right->fr = p.fr;
            left->l = p.l; left->r = m; left->fl = p.fl; left->fm = flm; left->fr = p.fm;
            right->tol = left->tol = p.tol / 2;
            right->depth = left->depth = p.depth + 1;
        }
    }
    return total;
}

/* plane[a]: the next plane x_a = plane[a] h the ray x0 + t dd meets beyond t, tp[a] its t;
 * inv = 1 / dd (products: divisions were a tenth of the march) */
inline void next_planes(const real *x0, const real *dd, const real *inv, const real t, const real h, int *plane,
                        real *tp)
{
    for (int a = 0; a < 3; a++) {
        const real x = x0[a] + t * dd[a];
        plane[a] = dd[a] > 0 ? (int)floor(x / h) + 1 : (int)ceil(x / h) - 1;
        tp[a] = dd[a] == 0 ? INFINITY : (plane[a] * h - x0[a]) * inv[a];
        while (tp[a] <= t) { /* x sat on a plane but rounded to its near side */
            plane[a] += dd[a] > 0 ? 1 : -1;
            tp[a] = (plane[a] * h - x0[a]) * inv[a];
        }
    }
}

/* past the planes met at tn: the next ones along those axes */
inline void step_planes(const real *x0, const real *dd, const real *inv, const real tn, const real h, int *plane,
                        real *tp)
{
    for (int a = 0; a < 3; a++)
        if (tp[a] <= tn) {
            plane[a] += dd[a] > 0 ? 1 : -1;
            tp[a] = (plane[a] * h - x0[a]) * inv[a];
        }
}

/* the block of `size` fine cells holding x, and the bound on |field| there (0 outside the blocks) */
inline real block_bound(__global const float *bound, const int4 origin, const int4 shape, const real3 x,
                        const int size, int4 *b)
{
    *b = convert_int4((real4)(floor(x / size), 0));
    const int4 k = *b - origin;
    if (k.x < 0 || k.y < 0 || k.z < 0 || k.x >= shape.x || k.y >= shape.y || k.z >= shape.z)
        return 0;
    return bound[((size_t)k.z * shape.y + k.y) * shape.x + k.x];
}

/* where the ray leaves block b of `size` fine cells (at most t1) */
inline real block_exit(const real *x0, const real *dd, const real *inv, const int4 b, const int size, const real t1)
{
    const int bb[3] = {b.x, b.y, b.z};
    real texit = t1;
    for (int a = 0; a < 3; a++)
        if (dd[a] != 0)
            texit = fmin(texit, ((bb[a] + (dd[a] > 0)) * size - x0[a]) * inv[a]);
    return texit;
}

/* The bounds on |field| for skipping and R: per CLW_BLOCK^3 block, and per superblock of CLW_SUPER^3
 * fine cells the largest of those; a superblock bounded by at most `coarse` is one region */
typedef struct {
    __global const float *block, *super;
    int4 block_origin, block_shape, super_origin, super_shape;
    real coarse;
} Regions;

/* The region of the ray around xm (segment [t, tn]) that one bound covers, and that bound: the
 * superblock when its bound is at most R->coarse (empty, or nearly: crossed in one step), else the
 * block.  Returns the bound; *end is where the ray leaves the region.  *fine_end caches where the
 * ray leaves the last superblock found above R->coarse, whose blocks need no second look. */
inline real region_bound(const real *x0, const real *dd, const real *inv, const real3 xm, const real tn,
                         const real t1, const Regions *R, real *fine_end, real *end)
{
    int4 b;
    if (!(tn <= *fine_end)) {
        const real sb = block_bound(R->super, R->super_origin, R->super_shape, xm, CLW_SUPER, &b);
        const real sexit = fmax(block_exit(x0, dd, inv, b, CLW_SUPER, t1), tn);
        if (sb <= R->coarse) {
            *end = sexit;
            return sb;
        }
        *fine_end = sexit;
    }
    const real bb = block_bound(R->block, R->block_origin, R->block_shape, xm, CLW_BLOCK, &b);
    *end = fmax(block_exit(x0, dd, inv, b, CLW_BLOCK, t1), tn);
    return bb;
}

/* (S4, S2): Simpson's rule over [-1, 1] on 4 and on 2 panels, from the values at xi = -1 + p/4,
 * p = 1..8 in the lanes of v and p = 0 in `first` */
inline real2 simpson_pair(const real8 v, const real first)
{
    const real8 w4 = v * (real8)(4, 2, 4, 2, 4, 2, 4, 1), w2 = v * (real8)(0, 4, 0, 2, 0, 4, 0, 1);
    return (real2)((dot(w4.lo + w4.hi, (real4)(1)) + first) / 12, (dot(w2.lo + w2.hi, (real4)(1)) + first) / 6);
}

/* raytrace: one ray per pixel.
 *
 * Parameters
 *   image        out (H, W) float4: premultiplied (R, G, B, 1 - T), or line integrals (CLW_XRAY)
 *   stats        out (H, W) int4: segments, segments shaded at the midpoint (no gradient), integrand
 *                    evaluations, flags
 *                    (bit 0 terminated early, bit 1 Simpson depth limit reached)
 *   coef, start, shape, offset   the fine grids (float4), per grid box (x, y, z) and first element
 *   bound, occ_origin, occ_shape bound on |field| per CLW_BLOCK^3 block (grid-0 fine coordinates / block)
 *   super_bound, super_origin, super_shape  the largest of those per superblock of CLW_SUPER^3 fine cells
 *   coarse_bound superblocks bounded by at most this are one region for skipping and R
 *   box_lo, box_hi               clip box of the model's support, grid-0 fine coordinates
 *   base, du, dv, dir            rays in world units: orthographic p = base + c du + r dv, w = dir;
 *                                perspective p = base (the eye), w = normalize(dir + c du + r dv),
 *                                with c, r the pixel centre's offsets from the image centre
 *   to_fine_scale, to_fine_offset  grid-0 fine coordinates = world * scale + offset
 *   nodes        the sample points xi_k (CLW_SAMPLES), then the (CLW_SAMPLES, CLW_SAMPLES) matrix
 *                from the samples to the field's Chebyshev series, then the (9, 9) one from lanes
 *                0..8 to the gradient's
 *   weights      (CLW_SAMPLES, 8) sample k's weights in the integral from -1 to xi = -1 + p/4,
 *                p = 1..8, of the polynomial through the samples (p = 8: the whole segment)
 *   tol          absolute tolerance per output value
 *   shade_gain   how much shading can scale the emission (the shaded q <= shade_gain |field|)
 *   grad_floor   shorter world gradients of alpha get no diffuse or specular light: on a plateau
 *                of alpha they are rounding noise, whose random normals would make the integrand
 *                jump everywhere
 *   lights       (nlights,) unit directions towards the lights; phong (ka, kd, ks, shininess)
 * Grid: global (W, H). */
__kernel void raytrace(__global float4 *image, __global int4 *stats, const int width, const int height,
                       FIELD_PARAMS,
                       __global const float *bound, const int4 occ_origin, const int4 occ_shape,
                       __global const float *super_bound, const int4 super_origin, const int4 super_shape,
                       const real coarse_bound,
                       const float4 box_lo, const float4 box_hi,
                       const float4 base, const float4 du, const float4 dv, const float4 dir, const int perspective,
                       const float4 to_fine_scale, const float4 to_fine_offset,
                       __constant const real *nodes, __constant const real *weights, const real tol,
                       const real shade_gain,
                       const real grad_floor,
                       __constant const float4 *lights, const int nlights, const float4 phong)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height)
        return;
    const Field G = FIELD_INIT;
    const real pc = (real)col + (real)0.5 - (real)width / 2, pr = (real)height / 2 - (real)row - (real)0.5;
    real3 p, w;
    if (perspective) {
        p = to_real3(base.xyz);
        w = normalize(to_real3(dir.xyz) + pc * to_real3(du.xyz) + pr * to_real3(dv.xyz));
    } else {
        p = to_real3(base.xyz) + pc * to_real3(du.xyz) + pr * to_real3(dv.xyz);
        w = to_real3(dir.xyz);
    }
    const real3 scale = to_real3(to_fine_scale.xyz);
    const real3 X0 = p * scale + to_real3(to_fine_offset.xyz);
    const real3 D = w * scale; /* fine units per world unit of t */

    /* clip to the support box (slabs) */
    real t0 = perspective ? 0 : -INFINITY, t1 = INFINITY;
    const real lo[3] = {box_lo.x, box_lo.y, box_lo.z}, hi[3] = {box_hi.x, box_hi.y, box_hi.z};
    const real x0[3] = {X0.x, X0.y, X0.z}, dd[3] = {D.x, D.y, D.z}, inv[3] = {1 / D.x, 1 / D.y, 1 / D.z};
    for (int a = 0; a < 3; a++) {
        if (dd[a] == 0) {
            if (x0[a] < lo[a] || x0[a] > hi[a])
                t1 = -INFINITY;
        } else {
            const real ta = (lo[a] - x0[a]) / dd[a], tb = (hi[a] - x0[a]) / dd[a];
            t0 = fmax(t0, fmin(ta, tb));
            t1 = fmin(t1, fmax(ta, tb));
        }
    }
    const Regions regions = {bound, super_bound, occ_origin, occ_shape, super_origin, super_shape, coarse_bound};
    const size_t pix = (size_t)row * width + col;
    Active active;
    active_init(&active, G, pix, X0, D);
    int segments = 0, midpoints = 0, evals = 0, flags = 0;
    if (!(t1 > t0)) {
        image[pix] = (float4)(0.0f);
        stats[pix] = (int4)(0);
        return;
    }

#ifndef CLW_XRAY
    Shading P;
    P.ka = phong.x; P.kd = phong.y; P.ks = phong.z; P.shininess = phong.w;
    P.grad_floor = grad_floor;
    P.nlights = min(nlights, 8);
    P.scale = scale;
    for (int i = 0; i < P.nlights; i++) {
        P.light[i] = to_real3(lights[i].xyz);
        P.halfway[i] = normalize(P.light[i] - w); /* halfway between the light and the viewer */
    }
    real T = 1;
    real3 I = (real3)(0);
    const real total = t1 - t0;
    real skip_budget = tol / 4;
    real shade_budget = tol * 3 / 8; /* three quarters of the quadrature's half, when shading */
    const real quadrature_share = SHADING ? tol / 8 : tol / 2;
    /* R(t0): the region bounds integrated along the whole ray, region by region */
    real rest = 0;
    {
        real tp[3];
        int plane[3];
        real fine_end = -INFINITY;
        next_planes(x0, dd, inv, t0, CLW_BLOCK, plane, tp);
        for (real t = t0; t < t1;) {
            const real tn = fmin(t1, fmin(tp[0], fmin(tp[1], tp[2])));
            real end;
            rest += region_bound(x0, dd, inv, X0 + (t + tn) / 2 * D, tn, t1, &regions, &fine_end, &end) * (end - t);
            if (end > tn) { /* a coarse superblock: on past it */
                t = end;
                next_planes(x0, dd, inv, t, CLW_BLOCK, plane, tp);
            } else {
                t = tn;
                step_planes(x0, dd, inv, tn, CLW_BLOCK, plane, tp);
            }
        }
    }
    /* R(t) = rest - consumed, the part of the sum at t' < t subtracted as the march passes it;
     * slack covers the rounding of the two sums (float32: ~1e-7 relative per term) */
    const real slack = rest * (real)1e-4;
    real consumed = 0;
#else
    real4 I = (real4)(0);
    real skip_budget = tol / 2;
#endif
    /* the last evaluated segment's end: where, the field, and (shaded point by point) the
     * shaded emission and alpha's gradient */
    real t_joined = -INFINITY;
    real4 end_field = (real4)(0);
#ifndef CLW_XRAY
    bool end_shaded = false;
    real3 end_emission = (real3)(0), end_gradient = (real3)(0);
#endif
    /* the block or coarse superblock the last segment lay in (its bound, where the ray leaves it),
     * and where the ray leaves the last fine superblock */
    real bnd = 0, texit = -INFINITY, fine_end = -INFINITY;
    const real h = CLW_LATTICE;
    real tp[3];
    int plane[3];
    real t = t0;
    bool replan = true;
    while (t < t1) {
        if (replan) { /* the next knot plane per axis, from the position at t */
            next_planes(x0, dd, inv, t, h, plane, tp);
            replan = false;
        }
        const real tn = fmin(t1, fmin(tp[0], fmin(tp[1], tp[2])));
        const real3 xm = X0 + (t + tn) / 2 * D;
        if (!(tn <= texit)) /* a new block or superblock: its bound, and where the ray leaves it */
            bnd = region_bound(x0, dd, inv, xm, tn, t1, &regions, &fine_end, &texit);
#ifdef CLW_XRAY
        const real cost = bnd * (texit - t);
#else
        const real rest_after = fmax(rest - consumed - bnd * (texit - t), (real)0) + slack;
        const real cost = T * bnd * (texit - t) * (shade_gain * (1 + rest_after) + 1);
#endif
        if (cost <= skip_budget) { /* (nearly) empty region: jump to where the ray leaves it */
            skip_budget -= cost;
#ifndef CLW_XRAY
            consumed += bnd * (texit - t);
#endif
            t = texit;
            replan = true;
            continue;
        }
        if (tn > t) {
            Segment S;
            Basis basis[CLW_GROUPS];
            S.radius = (tn - t) / 2;
            S.series = false;
            /* p = 0 from the last segment's p = 8 when it ended here (and the field is C^1) */
            const bool joined = JOIN && t == t_joined;
            sample_segment(G, &active, (t + tn) / 2, xm, S.radius, D, nodes, !joined, S.fq, basis);
            if (joined)
                S.fq[P0] = end_field;
            end_field = S.fq[7];
            t_joined = tn;
            segments += 1;
#ifdef CLW_XRAY /* the integral over the segment */
            real4 integral = (real4)(0);
            for (int k = 0; k < NS; k++)
                integral += S.fq[k] * weights[8 * k + 7];
            I += S.radius * integral;
#else
            /* the field at p = 1..8 per channel, alpha's integral from -1 to there, and p = 0 */
            real lr[8], lg[8], lb[8], la[8];
            real8 A8 = 0;
            for (int k = 0; k < NS; k++) {
                /* alpha and q clamped at 0 (thresholding can make them dip below); q stays a
                 * polynomial for the series (shade clamps it wherever it is evaluated): the
                 * interpolant of clamped samples would oscillate by up to the points' Lebesgue
                 * constant times the dip */
                const real4 v = fmax(S.fq[k], (real4)(0));
                S.fq[k].w = v.w;
                if (k < 8) {
                    lr[k] = v.x; lg[k] = v.y; lb[k] = v.z; la[k] = v.w;
                }
                A8 = fma((real8)(v.w), vload8(k, weights), A8);
            }
            real8 r8 = vload8(0, lr), g8 = vload8(0, lg), b8 = vload8(0, lb);
            const real8 a8 = vload8(0, la);
            const real4 f0 = fmax(S.fq[P0], (real4)(0));
            const real depth = A8.s7; /* int alpha dxi over the segment */
            const real8 att = fast_exp(-S.radius * A8);
            bool simpson_full = true; /* adaptive Simpson on the shaded integrand */
            real3 part;
#ifdef CLW_SHADE
            {   /* Shading turns q into q (ka + kd D) + ks alpha S with D, S in [0, nlights]: the
                 * midpoint of that range errs by at most half its width, times the unshaded
                 * integrals (Simpson on 4 panels, plus |S4 - S2| for their error).  A segment whose
                 * error that way fits in what is left of the shading budget takes the midpoint
                 * and needs no gradient. */
                const real2 sr = simpson_pair(r8 * att, f0.x), sg = simpson_pair(g8 * att, f0.y),
                            sb = simpson_pair(b8 * att, f0.z), sa = simpson_pair(a8 * att, f0.w);
                const real3 s4 = (real3)(sr.x, sg.x, sb.x), ds = fabs(s4 - (real3)(sr.y, sg.y, sb.y));
                const real dsa = fabs(sa.x - sa.y);
                const real n = P.nlights, diffuse_mid = P.ka + P.kd * n / 2, specular_mid = P.ks * n / 2;
                const real3 err = P.kd * n / 2 * (s4 + ds) + specular_mid * (sa.x + dsa) /* the range */
                                  + diffuse_mid * ds + specular_mid * dsa;            /* the quadrature */
                const real cost = T * S.radius * fmax(err.x, fmax(err.y, err.z));
                if (cost <= shade_budget) {
                    shade_budget -= cost;
                    part = diffuse_mid * s4 + specular_mid * sa.x;
                    simpson_full = false;
                    midpoints += 1;
                    evals += 9;
                }
            }
#endif
            if (simpson_full) {
                /* the shaded emission at p = 0 (and alpha's gradient there) from the last segment
                 * when that was shaded point by point too */
                const bool shaded_joined = joined && end_shaded;
                real3 f9[9];
#ifdef CLW_SHADE
                sample_gradient(basis, !shaded_joined, &S.gx, &S.gy, &S.gz);
                if (shaded_joined) {
                    S.gx.s8 = end_gradient.x; S.gy.s8 = end_gradient.y; S.gz.s8 = end_gradient.z;
                }
                end_gradient = (real3)(S.gx.s7, S.gy.s7, S.gz.s7);
#else
                S.gx = 0; S.gy = 0; S.gz = 0; /* unshaded: shade8 and shade only clamp */
#endif
                shade8(&r8, &g8, &b8, a8, S.gx.lo, S.gy.lo, S.gz.lo, &P);
                if (shaded_joined) {
                    f9[0] = end_emission;
                } else {
                    real r = f0.x, gr = f0.y, b = f0.z;
                    shade(&r, &gr, &b, f0.w, S.gx.s8, S.gy.s8, S.gz.s8, &P);
                    f9[0] = (real3)(r, gr, b);
                }
                end_emission = (real3)(r8.s7, g8.s7, b8.s7);
                real fr[8], fg[8], fb[8];
                vstore8(r8 * att, 0, fr);
                vstore8(g8 * att, 0, fg);
                vstore8(b8 * att, 0, fb);
                for (int p = 1; p <= 8; p++)
                    f9[p] = (real3)(fr[p - 1], fg[p - 1], fb[p - 1]);
                const real seg_tol = quadrature_share * (tn - t) / total / T;
                part = simpson(&S, &P, f9, nodes, seg_tol / S.radius, &evals, &flags);
            }
            end_shaded = simpson_full;
            I += T * S.radius * part;
            T *= exp(-S.radius * depth);
            consumed += bnd * (tn - t);
            const real left = fmax(rest - consumed, (real)0) + slack;
            if (T * fmax(fmin((real)1, left), shade_gain * left) <= tol / 4) {
                flags |= 1;
                break;
            }
#endif
        }
        t = tn;
        step_planes(x0, dd, inv, tn, h, plane, tp);
    }
#ifdef CLW_XRAY
    image[pix] = convert_float4(I);
#else
    image[pix] = (float4)(convert_float3(I), (float)(1 - T));
#endif
    stats[pix] = (int4)(segments, midpoints, evals, flags | active_flags(&active));
}
