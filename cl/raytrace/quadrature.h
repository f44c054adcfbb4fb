/* quadrature.h: one segment's integrals (docs/raytracing.md §2): the Chebyshev series of the
 * samples, Phong shading of the emission, and adaptive Simpson on the shaded integrand. */
#ifndef CLW_QUADRATURE_H
#define CLW_QUADRATURE_H
#include "raytrace/types.h"

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
    realv gx, gy, gz; /* the gradient of alpha there (fine units), lanes 0..NG-1 */
    real radius;     /* half the segment length in world units */
    bool series;     /* q, g, A below are made (only panels finer than quarters need them) */
    real4 q[NS];     /* field series (q_R, q_G, q_B, alpha) in xi in [-1, 1] */
    real3 g[NG];     /* gradient-of-alpha series (fine units), of degree <= NG - 1 */
    real A[NS + 1];  /* antiderivative of alpha in xi, zero at xi = -1 (times radius = optical depth) */
} Segment;

/* the Chebyshev series g of the gradient's lanes 0..NG-1 (nodes: after the points and the field's matrix) */
inline void lane_series(const realv gxv, const realv gyv, const realv gzv, __constant const real *nodes, real3 *g)
{
    real gx[16], gy[16], gz[16];
    vstore16(gxv, 0, gx);
    vstore16(gyv, 0, gy);
    vstore16(gzv, 0, gz);
    for (int m = 0; m < NG; m++) {
        real3 ag = (real3)(0);
        for (int k = 0; k < NG; k++)
            ag += (real3)(gx[k], gy[k], gz[k]) * nodes[NS + NS * NS + m * NG + k];
        g[m] = ag;
    }
}

inline void gradient_series(Segment *S, __constant const real *nodes) { lane_series(S->gx, S->gy, S->gz, nodes, S->g); }

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
    gradient_series(S, nodes);
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
    int whole, exponent; /* shininess a whole number up to 64: powers by squaring */
    real grad_floor; /* world gradients of alpha this short are flat: no normal, ambient light only */
    int nlights;
    real3 light[CLW_MAX_LIGHTS], halfway[CLW_MAX_LIGHTS];
    real3 scale;     /* fine units per world unit, per axis: world gradient = fine gradient * scale */
} Shading;

#ifdef CLW_SHADE
#define SHADING 1
#else
#define SHADING 0
#endif

/* c^shininess for c > 0, by squaring where the shininess is a whole number up to 64 (the usual case: exact,
 * and 5-7 % of the render cheaper than the logarithms), else as exp2(shininess log2 c): PoCL's pow goes
 * through extended-precision logarithms and took a quarter of the render time */
#define POWER(TYPE, NAME)                                                                            \
    inline TYPE NAME(const TYPE c, const Shading *P)                                                 \
    {                                                                                                \
        if (P->whole) {                                                                              \
            TYPE out = (TYPE)(1), base = c;                                                          \
            for (int e = P->exponent; e > 0; e >>= 1) {                                              \
                out = (e & 1) ? out * base : out;                                                    \
                base *= base;                                                                        \
            }                                                                                        \
            return out;                                                                              \
        }                                                                                            \
        return fast_exp2(P->shininess * fast_log2(c));                                               \
    }

/* The shaded emission of eq. 4, (r, g, b) in place, from the field (r, g, b, a) and the fine
 * gradient of alpha (gx, gy, gz): one point (TYPE real) or eight at once (real8; the comparisons
 * and ?: then act per lane, so the same text serves both). */
#define SHADE(TYPE, NAME, POWER_OF)                                                                  \
    inline void NAME(TYPE *r, TYPE *g, TYPE *b, const TYPE a, const TYPE gx, const TYPE gy, const TYPE gz, \
                     const Shading *P)                                                               \
    {                                                                                                \
        *r = fmax(*r, (TYPE)(0)); *g = fmax(*g, (TYPE)(0)); *b = fmax(*b, (TYPE)(0));                \
        if (!SHADING)                                                                                \
            return;                                                                                  \
        const TYPE wx = gx * P->scale.x, wy = gy * P->scale.y, wz = gz * P->scale.z;                 \
        const TYPE len = sqrt(wx * wx + wy * wy + wz * wz);                                          \
        /* outward: alpha decreases along n (docs/raytracing.md §5); flat below grad_floor */               \
        const TYPE flat = len > P->grad_floor ? (TYPE)(0) : (TYPE)(1);                               \
        const TYPE inv = -1 / (len + flat);                                                          \
        const TYPE nx = wx * inv, ny = wy * inv, nz = wz * inv;                                      \
        TYPE diffuse = (TYPE)(0), specular = (TYPE)(0);                                              \
        for (int i = 0; i < P->nlights; i++) {                                                       \
            diffuse += fmax(nx * P->light[i].x + ny * P->light[i].y + nz * P->light[i].z, (TYPE)(0)); \
            const TYPE c = nx * P->halfway[i].x + ny * P->halfway[i].y + nz * P->halfway[i].z;       \
            specular += c > 0 ? POWER_OF(c, P) : (TYPE)(P->shininess == 0);                         \
        }                                                                                            \
        diffuse = flat > 0 ? (TYPE)(0) : diffuse;                                                    \
        specular = flat > 0 ? (TYPE)(0) : P->ks * fmax(a, (TYPE)(0)) * specular;                     \
        const TYPE lit = P->ka + P->kd * diffuse;                                                    \
        *r = *r * lit + specular; *g = *g * lit + specular; *b = *b * lit + specular;                \
    }
POWER(real, power)
POWER(real8, power8)
SHADE(real, shade, power)
SHADE(real8, shade8, power8)

/* (S4, S2): Simpson's rule over [-1, 1] on 4 and on 2 panels, from the values at xi = -1 + p/4,
 * p = 1..8 in the lanes of v and p = 0 in `first` */
inline real2 simpson_pair(const real8 v, const real first)
{
    const real8 w4 = v * (real8)(4, 2, 4, 2, 4, 2, 4, 1), w2 = v * (real8)(0, 4, 0, 2, 0, 4, 0, 1);
    return (real2)((dot(w4.lo + w4.hi, (real4)(1)) + first) / 12, (dot(w2.lo + w2.hi, (real4)(1)) + first) / 6);
}

/* Midpoint shading (docs/raytracing.md §5).  Shading turns q into q (ka + kd D) + ks alpha S with D, S in
 * [0, nlights]: the midpoint of that range errs by at most half its width, times the unshaded integrals
 * (Simpson on 4 panels, plus |S4 - S2| for their error).  From the unshaded q e^{-A} and alpha e^{-A} at
 * xi = -1 + p/4 (p = 1..8 in the lanes of r, g, b, a; p = 0 in f0), the segment takes the midpoint when that
 * error, times `weight` (T radius: what a unit of the segment's integral is worth in the image), fits in
 * *budget: then *part is its int q' e^{-A} dxi, the cost is taken from *budget, and it needs no gradient. */
inline bool midpoint_shading(const real8 r, const real8 g, const real8 b, const real8 a, const real4 f0,
                             const Shading *P, const real weight, real *budget, real3 *part)
{
    const real2 sr = simpson_pair(r, f0.x), sg = simpson_pair(g, f0.y), sb = simpson_pair(b, f0.z),
                sa = simpson_pair(a, f0.w);
    const real3 s4 = (real3)(sr.x, sg.x, sb.x), ds = fabs(s4 - (real3)(sr.y, sg.y, sb.y));
    const real dsa = fabs(sa.x - sa.y);
    const real n = P->nlights, diffuse_mid = P->ka + P->kd * n / 2, specular_mid = P->ks * n / 2;
    const real3 err = P->kd * n / 2 * (s4 + ds) + specular_mid * (sa.x + dsa) /* the range */
                      + diffuse_mid * ds + specular_mid * dsa;            /* the quadrature */
    const real cost = weight * fmax(err.x, fmax(err.y, err.z));
    if (cost > *budget)
        return false;
    *budget -= cost;
    *part = diffuse_mid * s4 + specular_mid * sa.x;
    return true;
}

/* q e^{-A} at xi from the series: the shaded emission attenuated inside the segment */
inline real3 integrand(const Segment *S, const Shading *P, const real xi)
{
    const real4 f = cheb4(S->q, NS, xi);
    const real3 g = cheb3(S->g, NG, xi);
    real r = f.x, gr = f.y, b = f.z;
    shade(&r, &gr, &b, f.w, g.x, g.y, g.z, P);
    return (real3)(r, gr, b) * fast_exp(-S->radius * cheb1(S->A, NS + 1, xi));
}

typedef struct {
    real l, r, tol;
    real3 fl, fm, fr;
    int depth; /* halvings from the whole segment */
} Panel;

/* Simpson on panel p and on its halves (values flm, fmr at its quarter points): when the two agree
 * within p's tolerance, or below the rounding floor, or at the depth limit (flagged), the
 * extrapolated sum is added to total and the panel is done.  Where the normal turns across the panel
 * (`turns`: normal_turns) the two rules may agree by chance, so the error counted is at least what the whole
 * panel adds, its width times its largest value: such a panel halves until it resolves the turn or adds too
 * little to matter (docs/raytracing.md §2). */
inline bool panel_done(const Panel *p, const real3 flm, const real3 fmr, const bool turns, real3 *total, int *flags)
{
    const real w = p->r - p->l;
    const real3 s1 = w / 6 * (p->fl + 4 * p->fm + p->fr);
    const real3 s2 = w / 12 * (p->fl + 4 * flm + 2 * p->fm + 4 * fmr + p->fr);
    const real3 d = fabs(s2 - s1);
    real err = fmax(d.x, fmax(d.y, d.z));
    if (turns) {
        const real3 big = fmax(fmax(fabs(p->fl), fabs(flm)), fmax(fmax(fabs(p->fm), fabs(fmr)), fabs(p->fr)));
        err = fmax(err, w * fmax(big.x, fmax(big.y, big.z)));
    }
    /* below the rounding floor of the arithmetic, halving the panel cannot help */
    const real floor_err = 16 * REAL_EPSILON * fmax(fabs(s2.x), fmax(fabs(s2.y), fabs(s2.z)));
    if (err <= fmax(15 * p->tol, floor_err) || p->depth >= CLW_MAX_DEPTH) {
        if (err > fmax(15 * p->tol, floor_err))
            *flags |= 2;
        *total += s2 + (s2 - s1) / 15;
        return true;
    }
    return false;
}

/* Whether the normal turns between the samples (docs/raytracing.md §2).  Simpson's test compares two rules on one
 * panel's five points, so a feature between them fools both alike; in the shaded emission that feature is the
 * normal -grad/|grad| turning fast where alpha's gradient nearly vanishes (a coarse segment 1.4 % off: the light
 * went out between two samples).  The gradient's lanes are exact samples of its polynomial; returns which of the
 * two first panels (bit 0: [l, mid], bit 1: [mid, r]) see the normal move by more than NORMAL_CHORD between
 * neighbouring samples (a flat gradient has no normal: no constraint).  Lanes 0..7: p = 1..8, lane 8: p = 0,
 * of xi = l + (r - l) p/8. */
#define NORMAL_CHORD 0.125f
inline int normal_turns(const realv gx, const realv gy, const realv gz, const Shading *P)
{
#ifdef CLW_SHADE
    /* chord > c between unit normals: cos < 1 - c^2/2 = k, i.e. w.v <= 0 or (w.v)^2 < k^2 |w|^2 |v|^2 */
    const realv x = gx * P->scale.x, y = gy * P->scale.y, z = gz * P->scale.z, len2 = x * x + y * y + z * z;
    const real8 dot = x.lo * x.s80123456 + y.lo * y.s80123456 + z.lo * z.s80123456;
    const real8 both = len2.lo * len2.s80123456;
    const real k = 1 - NORMAL_CHORD * NORMAL_CHORD / 2, floor2 = P->grad_floor * P->grad_floor;
    const real8 turned = select((real8)(0), (real8)(1), (dot <= 0 || dot * dot < k * k * both)
                                                         && fmin(len2.lo, len2.s80123456) > floor2);
    return (any(turned.lo > 0) ? 1 : 0) | (any(turned.hi > 0) ? 2 : 0);
#else
    return 0;
#endif
}

/* normal_turns from the gradient series g (degree NG - 1 in xi) at the n + 1 points l + (r - l) p/n: n = 8 for
 * both first panels of [l, r], 4 for [l, r] as one panel (bit 0) */
inline int series_turns(const real3 *g, const Shading *P, const real l, const real r, const int n)
{
#ifdef CLW_SHADE
    real lx[16], ly[16], lz[16];
    real3 v;
    for (int p = 0; p <= 8; p++) { /* points past the n-th repeat it: no turn there */
        if (p <= n)
            v = cheb3(g, NG, l + (r - l) * p / n);
        const int lane = p == 0 ? 8 : p - 1;
        lx[lane] = v.x; ly[lane] = v.y; lz[lane] = v.z;
    }
    return normal_turns(vload16(0, lx), vload16(0, ly), vload16(0, lz), P);
#else
    return 0;
#endif
}

/* ADAPTIVE_SIMPSON(NAME, CTX, EVAL): int_l^r f dxi by adaptive Simpson from 2 panels, for an integrand
 * f = EVAL(ctx, P, nodes, xi) and its gradient series ctx->g (made by EVAL); counts evaluations, flags depth.
 * f9 holds f at xi = l + (r - l) p/8, p = 0..8: the 2 panels and their halves, so EVAL is needed only when a
 * panel must halve again (nearly never at tolerance 1e-2); turns: normal_turns of the 2 panels.  Depth first,
 * right half pushed first: the stack holds at most one panel per depth. */
#define ADAPTIVE_SIMPSON(NAME, CTX, EVAL)                                                                     \
    inline real3 NAME(CTX *S, const Shading *P, const real3 *f9, __constant const real *nodes, const real l,   \
                      const real r, const real tol, const int turns, int *evals, int *flags)                  \
    {                                                                                                         \
        const real mid = (l + r) / 2;                                                                         \
        const Panel first = {l, mid, tol / 2, f9[0], f9[2], f9[4], 1},                                        \
                    second = {mid, r, tol / 2, f9[4], f9[6], f9[8], 1};                                       \
        real3 total = (real3)(0);                                                                             \
        *evals += 9;                                                                                          \
        Panel stack[CLW_MAX_DEPTH + 1];                                                                       \
        int top = 0;                                                                                          \
        if (panel_done(&first, f9[1], f9[3], turns & 1, &total, flags)) {                                     \
            if (panel_done(&second, f9[5], f9[7], turns & 2, &total, flags))                                  \
                return total;                                                                                 \
            stack[top++] = second;                                                                            \
        } else {                                                                                              \
            stack[top++] = second;                                                                            \
            stack[top++] = first;                                                                             \
        }                                                                                                     \
        while (top > 0) {                                                                                     \
            const Panel p = stack[--top];                                                                     \
            const real m = (p.l + p.r) / 2;                                                                   \
            real3 flm, fmr;                                                                                   \
            bool turned;                                                                                      \
            if (p.depth == 1) {                                                                               \
                flm = f9[p.l < mid ? 1 : 5];                                                                  \
                fmr = f9[p.l < mid ? 3 : 7];                                                                  \
                turned = turns & (p.l < mid ? 1 : 2);                                                         \
            } else {                                                                                          \
                flm = EVAL(S, P, nodes, (p.l + m) / 2);                                                       \
                fmr = EVAL(S, P, nodes, (m + p.r) / 2);                                                       \
                *evals += 2;                                                                                  \
                turned = series_turns(S->g, P, p.l, p.r, 4);                                                  \
            }                                                                                                 \
            if (!panel_done(&p, flm, fmr, turned, &total, flags)) {                                           \
                Panel *right = &stack[top++], *left = &stack[top++];                                          \
                right->l = m; right->r = p.r; right->fl = p.fm; right->fm = fmr; right->fr = p.fr;            \
                left->l = p.l; left->r = m; left->fl = p.fl; left->fm = flm; left->fr = p.fm;                 \
                right->tol = left->tol = p.tol / 2;                                                           \
                right->depth = left->depth = p.depth + 1;                                                     \
            }                                                                                                 \
        }                                                                                                     \
        return total;                                                                                         \
    }

/* the pre-classified integrand at xi, its series made when first needed */
inline real3 segment_point(Segment *S, const Shading *P, __constant const real *nodes, const real xi)
{
    if (!S->series)
        segment_series(S, nodes);
    return integrand(S, P, xi);
}

ADAPTIVE_SIMPSON(segment_simpson, Segment, segment_point)

/* int_{-1}^{1} q e^{-A} dxi of a segment (its gradient at the lanes: normal_turns) */
inline real3 simpson(Segment *S, const Shading *P, const real3 *f9, __constant const real *nodes, const real tol,
                     int *evals, int *flags)
{
    return segment_simpson(S, P, f9, nodes, -1, 1, tol, normal_turns(S->gx, S->gy, S->gz, P), evals, flags);
}
#endif
