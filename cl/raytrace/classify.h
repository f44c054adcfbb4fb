/* classify.h: post-classification, a transfer function applied while rendering (docs/raytracing.md §10).
 *
 * On a segment the scalar s is a polynomial in xi (degree NS - 1 at most) known exactly from its
 * samples.  The transfer function is piecewise linear in u = s scale + shift, so where u stays inside
 * one of its intervals, opacity and colour are polynomials in xi and the optical depth is exact.  The
 * segment is cut where u crosses a breakpoint: the Bernstein coefficients of u on a span bound its range
 * (convex hull); where they change sign once about a breakpoint, the span holds exactly one crossing,
 * found by bisection, and is cut there; other spans that straddle are halved (de Casteljau).  Each
 * piece's emission integral comes from adaptive Simpson on the classified, shaded integrand
 * (quadrature.h), its tolerance the piece's share of the segment's; when shading, the piece is cut again where
 * grad s . L changes sign for a light L (or halfway vector), since the normal flips there and n . L jumps or
 * kinks (found the same way, on grad s . L's Bernstein coefficients; bernstein.h).  The common case is cheap
 * (post_segment, post_gradient): a segment transparent by its hull needs nothing more; one inside one interval is
 * shaded by the ambient term alone where s falls along the ray away from a headlight (interval_unlit), or takes the
 * midpoint shading (neither needs the gradient), or Simpson on its samples where the shading does not turn on it.
 *
 * The table `tf` and its searches: tf_table.h.  Build: CLW_POST; nodes as bernstein.h says. */
#ifndef CLW_CLASSIFY_H
#define CLW_CLASSIFY_H
#include "raytrace/quadrature.h"
#include "raytrace/bernstein.h"
#include "raytrace/tf_table.h"

#define POST_DEPTH 16 /* spans are halved at most this often; a span still straddling is flagged */
#define POST_CUTS 4096 /* and a segment cut at most this often (a crossing each, the function's points permitting) */

/* One piece of a segment: u's series, its antiderivative, the gradient series of s (shading) and the
 * transfer function's linear interval on the piece */
typedef struct {
    real us[NS], ui[NS + 1]; /* u's Chebyshev series, and its antiderivative (any constant) */
    real3 g[NG];             /* the gradient of s (fine units), Chebyshev series */
    real radius;             /* half the segment length (world units) */
    real a, ui_a, depth_a;   /* the piece's start, ui there, and int alpha dxi from -1 to there */
    real4 line;              /* (u_ref, alpha_ref, alpha_slope, normal sign) */
    real3 rgb, rgb_slope;    /* colour at u_ref and per unit u */
} Piece;

/* int alpha dxi from the piece's start to xi (exact: alpha is linear in u there), for e^{-A} inside the piece */
inline real piece_depth(const Piece *C, const real xi)
{
    const real du_int = cheb1(C->ui, NS + 1, xi) - C->ui_a - C->line.x * (xi - C->a);
    return C->line.y * (xi - C->a) + C->line.z * du_int;
}

/* int alpha dxi over the whole piece [a, b] by 5-point Gauss-Legendre (8-point for 16 samples): exact for alpha's
 * degree (at most NS - 1), and free of the cancellation in piece_depth's differences where the transfer function
 * is steep.  x, w: the non-negative nodes and their weights; the centre (x = 0, 5 points) counts once */
inline real piece_total(const Piece *C, const real a, const real b)
{
#if NS > 10
    const int n = 4, first_pair = 0;
    const real x[4] = {(real)0.183434642495649805, (real)0.525532409916328986, (real)0.796666477413626740,
                       (real)0.960289856497536232};
    const real w[4] = {(real)0.362683783378361983, (real)0.313706645877887287, (real)0.222381034453374471,
                       (real)0.101228536290376259};
#else
    const int n = 3, first_pair = 1;
    const real x[3] = {0, (real)0.538469310105683091, (real)0.906179845938663993};
    const real w[3] = {(real)0.568888888888888889, (real)0.478628670499366468, (real)0.236926885056189088};
#endif
    real sum = 0;
    for (int i = 0; i < n; i++)
        for (int side = -1; side <= (i >= first_pair ? 1 : -1); side += 2) {
            const real u = cheb1(C->us, NS, (a + b) / 2 + side * x[i] * (b - a) / 2);
            sum += w[i] * fmax(C->line.y + C->line.z * (u - C->line.x), (real)0);
        }
    return sum * (b - a) / 2;
}

/* the shaded emission times e^{-A} at xi (A from the segment's start) */
inline real3 piece_point(Piece *C, const Shading *P, __constant const real *nodes, const real xi)
{
    const real du = cheb1(C->us, NS, xi) - C->line.x;
    const real alpha = fmax(C->line.y + C->line.z * du, (real)0);
    const real3 rgb = clamp(C->rgb + C->rgb_slope * du, (real)0, (real)1) * alpha;
    real r = rgb.x, g = rgb.y, b = rgb.z;
#ifdef CLW_SHADE
    const real3 grad = cheb3(C->g, NG, xi) * C->line.w;
    shade(&r, &g, &b, alpha, grad.x, grad.y, grad.z, P);
#else
    shade(&r, &g, &b, alpha, 0, 0, 0, P);
#endif
    return (real3)(r, g, b) * fast_exp(-C->radius * (C->depth_a + piece_depth(C, xi)));
}

ADAPTIVE_SIMPSON(piece_simpson, Piece, piece_point)

/* the i-th direction whose sign of grad s . d matters to the shading: light i / 2 (even i), or its halfway vector
 * (odd i) when there is a specular term and it differs from the light; world gradient: the fine one times P->scale.
 * false: none */
inline bool shading_direction(const Shading *P, const int i, real3 *d)
{
    if (i % 2 && (P->ks == 0 || all(P->halfway[i / 2] == P->light[i / 2])))
        return false;
    *d = (i % 2 ? P->halfway[i / 2] : P->light[i / 2]) * P->scale;
    return true;
}

/* Where the shading may jump or kink inside [a, b]: the sign changes of grad s . L for each light L and of
 * grad s . H for its halfway vector H when there is a specular term, from the gradient lanes 0..8 (whole segment,
 * `lanes`) or C's series; returns how many, in cuts */
inline int shading_cuts(const Piece *C, const Shading *P, __constant const real *nodes, const bool lanes,
                        const real *gx, const real *gy, const real *gz, const real a, const real b, real *cuts)
{
    int n = 0;
#ifdef CLW_SHADE
    real3 g[9], d;
    for (int j = 0; j < 9; j++)
        g[j] = lanes ? (real3)(gx[j], gy[j], gz[j])
                     : cheb3(C->g, 9, a + (b - a) * (nodes[j] + 1) / 2);
    for (int i = 0; i < 2 * P->nlights; i++) {
        if (!shading_direction(P, i, &d))
            continue;
        real v[9];
        for (int j = 0; j < 9; j++)
            v[j] = dot(g[j], d);
        sign_changes(v, nodes, a, b, cuts, &n);
    }
#endif
    return n;
}

/* Whether the shading may jump or kink on the segment (shading_cuts would cut it), from the gradient lanes */
inline bool shading_turns(const realv gx, const realv gy, const realv gz, const Shading *P,
                          __constant const real *nodes)
{
#ifdef CLW_SHADE
    real3 d;
    for (int i = 0; i < 2 * P->nlights; i++) {
        if (!shading_direction(P, i, &d))
            continue;
        real v[16], c[9];
        vstore16(gx * d.x + gy * d.y + gz * d.z, 0, v);
        if (coefficient_sign_changes(c, bernstein9(v, nodes, c)))
            return true;
    }
#endif
    return false;
}

/* int of piece_point over [a, b] cut at cuts[0..n): adaptive Simpson on each part with its share of tol;
 * f9: the first nine points of [a, b] when n = 0 */
inline real3 cut_simpson(Piece *C, const Shading *P, __constant const real *nodes, const real3 *f9, const real *cuts,
                         const int n, const real a, const real b, const real tol, int *evals, int *flags)
{
    if (n == 0 && f9)
        return piece_simpson(C, P, f9, nodes, a, b, tol, series_turns(C->g, P, a, b, 8), evals, flags);
    real3 sum = (real3)(0);
    real l = a;
    for (int i = 0; i <= 2 * n + 1; i++) {
        const real r = i % 2 == 0 ? (l + (i / 2 < n ? cuts[i / 2] : b)) / 2 : (i / 2 < n ? cuts[i / 2] : b);
        real3 g9[9];
        for (int p = 0; p <= 8; p++)
            g9[p] = piece_point(C, P, nodes, l + (r - l) * p / 8);
        sum += piece_simpson(C, P, g9, nodes, l, r, tol * (r - l) / (b - a), series_turns(C->g, P, l, r, 8), evals,
                             flags);
        l = r;
    }
    return sum;
}

/* The piece [a, b] of the segment, lying in the transfer function's interval k: its emission added to
 * *emission and its int alpha dxi to C->depth_a.  `unresolved`: a span still straddling points, classified as at
 * its midpoint all along (the interval's line beyond its interval could make the optical depth negative) */
inline void add_piece(Piece *C, const Shading *P, __constant const real *nodes, __global const real4 *tf,
                      const int K, const real a, const real b, const real tol, const bool unresolved,
                      real3 *emission, int *evals, int *flags)
{
    const real um = cheb1(C->us, NS, (a + b) / 2);
    const int k = tf_interval(tf, K, um);
    real4 line = tf[1 + K + 3 * k];
    C->rgb = tf[2 + K + 3 * k].xyz;
    C->rgb_slope = tf[3 + K + 3 * k].xyz;
    const real sign = line.z < 0 ? -1 : 1; /* normals face where alpha decreases */
    if (unresolved) {
        C->rgb += C->rgb_slope * (um - line.x);
        C->rgb_slope = 0;
        line = (real4)(um, fmax(line.y + line.z * (um - line.x), (real)0), 0, 0);
    }
    if (line.y == 0 && line.z == 0) /* transparent: nothing emitted, nothing absorbed */
        return;
    C->line = (real4)(line.xyz, sign);
    C->a = a;
    C->ui_a = cheb1(C->ui, NS + 1, a);
    real cuts[SHADE_CUTS];
    const int n = shading_cuts(C, P, nodes, false, 0, 0, 0, a, b, cuts);
    *emission += cut_simpson(C, P, nodes, 0, cuts, n, a, b, tol * (b - a) / 2, evals, flags);
    C->depth_a += piece_total(C, a, b);
}

/* A segment's scalar as the classification needs it, from s at the samples (lane order of fq): u there and its
 * Bernstein coefficients c on [-1, 1].  Returns whether the transfer function is opaque anywhere in the
 * coefficients' hull: a segment where it is not adds nothing, and needs no gradient. */
inline bool segment_scalar(const real *s, __constant const real *nodes, __global const real4 *tf, real *u, real *c)
{
    const real4 head = tf[0];
    const int K = (int)head.z;
    for (int k = 0; k < NS; k++)
        u[k] = s[k] * head.x + head.y;
    for (int m = 0; m < NS; m++) {
        real bm = 0;
        for (int k = 0; k < NS; k++)
            bm += u[k] * nodes[NS + NS * NS + NG * NG + m * NS + k];
        c[m] = bm;
    }
    real lo = c[0], hi = c[0];
    for (int i = 1; i < NS; i++) {
        lo = fmin(lo, c[i]);
        hi = fmax(hi, c[i]);
    }
    return tf_peak(tf, K, lo, hi) > 0;
}

/* How many breakpoints lie inside the hull of the Bernstein coefficients c by more than u is known to (the
 * samples' rounding times the interpolation's Lebesgue constant, about 30 for these points: a crossing by less
 * moves nothing measurable); *cross: of those u crosses exactly once, the nearest u's start (the lowest where u
 * rises, the highest where it falls), 0 for none: cut there first, a segment crossing many is cut at each in turn */
inline int breakpoints_inside(__global const real4 *tf, const int K, const real *c, int *cross)
{
    real lo = c[0], hi = c[0];
    for (int i = 1; i < NS; i++) {
        lo = fmin(lo, c[i]);
        hi = fmax(hi, c[i]);
    }
    const real eps = 64 * REAL_EPSILON * (1 + fmax(fabs(lo), fabs(hi)));
    const int first = tf_count(tf, K, lo + eps, true), end = tf_count(tf, K, hi - eps, false);
    const bool falls = c[NS - 1] < c[0]; /* those inside from u's start, up to the first crossed once */
    *cross = 0;
    for (int i = falls ? end : first + 1; (falls ? i > first : i <= end) && !*cross; i += falls ? -1 : 1)
        if (one_crossing(c, tf[i].x, eps))
            *cross = i;
    return max(end - first, 0);
}

/* A segment inside one interval of the transfer function: the interval's line, alpha at the samples and the
 * optical depth from -1 to xi = -1 + p/4 (p = 1..8, `weights`: exact, alpha being a polynomial of u's degree there),
 * e^{-radius depth} there, and u - u_ref at the samples */
typedef struct {
    bool transparent;
    real4 line;          /* (u_ref, alpha_ref, alpha_slope, 0) */
    real3 rgb, slope;    /* colour at u_ref and per unit u */
    real8 du, alpha, att; /* lanes 0..7: xi = -1 + p/4, p = 1..8 */
    real du0, alpha0;    /* lane P0: xi = -1 */
    real depth;          /* int alpha dxi over the segment */
} OneInterval;

/* Whether the segment lies inside one interval (no breakpoint inside the hull of u's Bernstein coefficients c),
 * and then O from u at the samples and the half length radius */
inline bool one_interval(const real *u, const real *c, __constant const real *weights, __global const real4 *tf,
                         const real radius, OneInterval *O)
{
    const int K = (int)tf[0].z;
    int cross;
    if (breakpoints_inside(tf, K, c, &cross))
        return false;
    const int k = tf_interval(tf, K, u[3]); /* xi = 0 */
    O->line = tf[1 + K + 3 * k];
    O->transparent = O->line.y == 0 && O->line.z == 0;
    O->rgb = tf[2 + K + 3 * k].xyz;
    O->slope = tf[3 + K + 3 * k].xyz;
    real alpha[NS];
    real8 depth = 0;
    for (int i = 0; i < NS; i++) {
        alpha[i] = fmax(O->line.y + O->line.z * (u[i] - O->line.x), (real)0);
        depth = fma((real8)(alpha[i]), vload8(i, weights), depth);
    }
    O->du = vload8(0, u) - O->line.x;
    O->du0 = u[P0] - O->line.x;
    O->alpha = vload8(0, alpha);
    O->alpha0 = alpha[P0];
    O->att = fast_exp(-radius * depth);
    O->depth = depth.s7;
    return true;
}

/* the unshaded emission rgb(u) alpha at the lanes 0..7 (r, g, b) and at P0 (*q0) */
inline void interval_emission(const OneInterval *O, real8 *r, real8 *g, real8 *b, real3 *q0)
{
    *r = clamp(O->rgb.x + O->slope.x * O->du, (real8)(0), (real8)(1)) * O->alpha;
    *g = clamp(O->rgb.y + O->slope.y * O->du, (real8)(0), (real8)(1)) * O->alpha;
    *b = clamp(O->rgb.z + O->slope.z * O->du, (real8)(0), (real8)(1)) * O->alpha;
    *q0 = clamp(O->rgb + O->slope * O->du0, (real)0, (real)1) * O->alpha0;
}

/* the segment's first nine points xi = -1 + p/4, p = 0..8, of the shaded emission times e^{-A}, from the gradient
 * lanes of s (lanes 0..7 and P0), eight at once as on the pre-classified path */
inline void interval_points(const OneInterval *O, const realv gx, const realv gy, const realv gz, const Shading *P,
                            real3 *f9)
{
    real8 r, g, b;
    real3 q0;
    interval_emission(O, &r, &g, &b, &q0);
    const real sign = O->line.z < 0 ? -1 : 1; /* normals face where alpha decreases */
    shade8(&r, &g, &b, O->alpha, gx.lo * sign, gy.lo * sign, gz.lo * sign, P);
    real q0r = q0.x, q0g = q0.y, q0b = q0.z;
    shade(&q0r, &q0g, &q0b, O->alpha0, gx.s8 * sign, gy.s8 * sign, gz.s8 * sign, P);
    f9[0] = (real3)(q0r, q0g, q0b);
    real fr[8], fg[8], fb[8];
    vstore8(r * O->att, 0, fr);
    vstore8(g * O->att, 0, fg);
    vstore8(b * O->att, 0, fb);
    for (int p = 1; p <= 8; p++)
        f9[p] = (real3)(fr[p - 1], fg[p - 1], fb[p - 1]);
}

/* Shaded at its midpoint where that is within what is left of the shading budget (midpoint_shading): weight is
 * what a unit of the segment's integrals is worth in the image (T radius).  Returns whether it was: then
 * *part = int q' e^{-A} dxi, and no gradient is needed. */
inline bool interval_midpoint(const OneInterval *O, const Shading *P, const real weight, real *budget, real3 *part)
{
    real8 r, g, b;
    real3 q0;
    interval_emission(O, &r, &g, &b, &q0);
    return midpoint_shading(r * O->att, g * O->att, b * O->att, O->alpha * O->att, (real4)(q0, O->alpha0), P,
                            weight, budget, part);
}

/* Turned away from a headlight all along (docs/raytracing.md §10): with one light L and the ray's direction w (unit,
 * world), ds/dt = grad s . w, so n . L = sign ds/dt / |grad s| + sign grad s . (-w - L) / |grad s| (n = -sign grad s /
 * |grad s|, sign: alpha's slope in the interval) is at most eps = |L + w| where sign ds/dt <= 0, which the Bernstein
 * coefficients c of u (u increasing with s) show when each step sign (c[i+1] - c[i]) is below minus their rounding.
 * The view direction is not an argument but H = (L - w) / |L - w| is: w = L - 2 (L . H) H, eps = 2 |L x H| (plus
 * 1e-6 for the inputs' rounding), and n . H <= eps + |H - L|.  There the diffuse factor lies in [0, eps] and the
 * specular one in [0, (eps + |H - L|)^shininess], so ka q is the shaded emission within kd eps q + ks (...) alpha,
 * charged with Simpson's |S4 - S2| to the shading budget as midpoint_shading does.  Returns whether it was taken:
 * then *part = int q' e^{-A} dxi, and no gradient is needed.  A light elsewhere (eps above 1e-3): never. */
inline bool interval_unlit(const OneInterval *O, const real *c, const Shading *P, const real weight, real *budget,
                           real3 *part)
{
#ifdef CLW_SHADE
    if (P->nlights != 1 || !(P->shininess > 0))
        return false;
    const real3 L = P->light[0], H = P->halfway[0];
    const real eps = 2 * length(cross(L, H)) + (real)1e-6;
    if (!(eps <= (real)1e-3 && dot(L, H) > 0))
        return false;
    const real sign = O->line.z < 0 ? -1 : 1;
    real big = 0;
    for (int i = 0; i < NS; i++)
        big = fmax(big, fabs(c[i]));
    const real rounding = 64 * REAL_EPSILON * (1 + big);
    for (int i = 0; i + 1 < NS; i++)
        if (!(sign * (c[i + 1] - c[i]) < -rounding))
            return false;
    real8 r, g, b;
    real3 q0;
    interval_emission(O, &r, &g, &b, &q0);
    const real2 sr = simpson_pair(r * O->att, q0.x), sg = simpson_pair(g * O->att, q0.y),
                sb = simpson_pair(b * O->att, q0.z), sa = simpson_pair(O->alpha * O->att, O->alpha0);
    const real3 s4 = (real3)(sr.x, sg.x, sb.x), ds = fabs(s4 - (real3)(sr.y, sg.y, sb.y));
    const real specular = P->ks * fast_exp2(P->shininess * fast_log2(fmin(eps + length(H - L), (real)1)));
    const real3 err = P->ka * ds + P->kd * eps * (s4 + ds) + specular * (sa.x + fabs(sa.x - sa.y));
    const real cost = weight * fmax(err.x, fmax(err.y, err.z));
    if (cost > *budget)
        return false;
    *budget -= cost;
    *part = P->ka * s4;
    return true;
#else
    return false;
#endif
}

/* Shaded point by point where the shading does not turn on the segment (shading_turns) and Simpson on the first
 * nine points is within tol on both panels (panel_done): returns whether it was, *emission = int q' e^{-A} dxi.
 * Otherwise classified_segment takes the segment (cuts, finer panels). */
inline bool interval_simpson(const OneInterval *O, const realv gx, const realv gy, const realv gz, const Shading *P,
                             __constant const real *nodes, const real tol, real3 *emission, int *evals)
{
    if (shading_turns(gx, gy, gz, P, nodes))
        return false;
    real3 f9[9], total = (real3)(0);
    interval_points(O, gx, gy, gz, P, f9);
    const Panel first = {-1, 0, tol / 2, f9[0], f9[2], f9[4], 1}, second = {0, 1, tol / 2, f9[4], f9[6], f9[8], 1};
    int flags = 0; /* panels at depth 1: never at the depth limit */
    const int turns = normal_turns(gx, gy, gz, P);
    if (!panel_done(&first, f9[1], f9[3], turns & 1, &total, &flags)
        || !panel_done(&second, f9[5], f9[7], turns & 2, &total, &flags))
        return false;
    *emission = total;
    *evals += 9;
    return true;
}

/* The whole segment inside one interval of the transfer function (the usual case), cut where the shading turns
 * (O: one_interval's): its samples are the first nine points where it needs no cut, as on the pre-classified path */
inline void add_segment(Piece *C, const OneInterval *O, const Shading *P, __constant const real *nodes,
                        const real *gx, const real *gy, const real *gz, const real tol, real3 *emission, int *evals,
                        int *flags)
{
    if (O->transparent)
        return;
    C->line = (real4)(O->line.xyz, O->line.z < 0 ? -1 : 1);
    C->rgb = O->rgb;
    C->rgb_slope = O->slope;
    C->a = -1;
    C->ui_a = cheb1(C->ui, NS + 1, -1);
    real cuts[SHADE_CUTS];
    const int n = shading_cuts(C, P, nodes, true, gx, gy, gz, -1, 1, cuts);
    real3 f9[9];
    if (n == 0)
        interval_points(O, vload16(0, gx), vload16(0, gy), vload16(0, gz), P, f9);
    *emission += cut_simpson(C, P, nodes, f9, cuts, n, -1, 1, tol, evals, flags);
    C->depth_a = O->depth;
}

/* u's Chebyshev series and antiderivative (any constant) from u at the samples: for pieces cut out of the
 * segment and Simpson's panels finer than quarters */
inline void piece_series(Piece *C, const real *u, __constant const real *nodes)
{
    for (int m = 0; m < NS; m++) {
        real am = 0;
        for (int k = 0; k < NS; k++)
            am += u[k] * nodes[NS + m * NS + k];
        C->us[m] = am;
    }
    /* C_k = (a'_{k-1} - a_{k+1}) / 2k, a'_0 = 2 a_0 */
    C->ui[0] = 0;
    for (int k = 1; k <= NS; k++)
        C->ui[k] = (C->us[k - 1] * (k == 1 ? 2 : 1) - (k + 1 < NS ? C->us[k + 1] : 0)) / (2 * k);
}

/* The classified segment: (int q' e^{-A} dxi, int alpha dxi) over xi in [-1, 1], from u at the samples and c, its
 * Bernstein coefficients (segment_scalar), the gradient of s at the samples (gx, gy, gz: lanes 0..NG-1) and its
 * series (grad; shading), the half length `radius` and the tolerance `tol` on the first (in xi units).  Flags bit 1
 * where a span could not be resolved. */
inline real4 classified_segment(real *c, const real *u, const real *gx, const real *gy, const real *gz,
                                const real3 *grad, const real radius, __constant const real *nodes,
                                __constant const real *weights, __global const real4 *tf, const Shading *P,
                                const real tol, int *evals, int *flags)
{
    const int K = (int)tf[0].z;
    Piece C;
    piece_series(&C, u, nodes);
    for (int m = 0; m < NG; m++)
        C.g[m] = grad[m];
    C.radius = radius;
    C.depth_a = 0;
    real3 emission = (real3)(0);
    OneInterval O;
    if (one_interval(u, c, weights, tf, radius, &O)) {
        add_segment(&C, &O, P, nodes, gx, gy, gz, tol, &emission, evals, flags);
        return (real4)(emission, C.depth_a);
    }
    /* spans left to right: the right parts wait on a stack */
    real stack_c[POST_DEPTH][NS], stack_ab[POST_DEPTH][2];
    int stack_depth[POST_DEPTH], top = 0, depth = 0, cut = 0;
    real a = -1, b = 1;
    while (true) {
        int cross;
        const int inside = breakpoints_inside(tf, K, c, &cross);
        if (inside == 0 || depth >= POST_DEPTH || cut >= POST_CUTS) { /* one interval (or unresolved: flagged) */
            if (inside)
                *flags |= 2;
            add_piece(&C, P, nodes, tf, K, a, b, tol, inside != 0, &emission, evals, flags);
            if (top == 0)
                break;
            top -= 1;
            for (int i = 0; i < NS; i++)
                c[i] = stack_c[top][i];
            a = stack_ab[top][0];
            b = stack_ab[top][1];
            depth = stack_depth[top];
            continue;
        }
        real x = (a + b) / 2; /* where the span is cut: its midpoint, or a crossing found by bisection */
        const real v = tf[cross].x;
        if (cross) {
            const real sa = c[0] - v;
            real l = a, r = b;
            for (int it = 0; it < POST_BISECTIONS && l < x && x < r; it++) {
                if ((cheb1(C.us, NS, x) - v) * sa > 0)
                    l = x;
                else
                    r = x;
                x = (l + r) / 2;
            }
        }
        real left[NS];
        bernstein_split(c, (x - a) / (b - a), left, stack_c[top]);
        if (cross) /* u = v at the cut, exactly: no part sees the crossing again */
            left[NS - 1] = stack_c[top][0] = v;
        stack_ab[top][0] = x;
        stack_ab[top][1] = b;
        /* a crossing's right part holds fewer points inside: it keeps its span's depth, so that a segment crossing
         * many points is cut at each (POST_CUTS at most); the stack never holds more parts than the depth */
        stack_depth[top++] = cross ? depth : depth + 1;
        depth += 1;
        cut += 1;
        for (int i = 0; i < NS; i++)
            c[i] = left[i];
        b = x;
    }
    return (real4)(emission, C.depth_a);
}
/* A segment of the post-classified ray (docs/raytracing.md §10), first without the gradient: from s at the samples,
 * u there and its Bernstein coefficients c (segment_scalar), and whether it lies inside one interval (*one, then
 * *O).  Returns true when it is done: transparent all along (*r = 0), or inside one interval, turned away from a
 * headlight (interval_unlit) or shaded at its midpoint, within what is left of the shading budget (*r = (int q'
 * e^{-A} dxi, int alpha dxi); weight: what a unit of those is worth in the image, T radius).  Otherwise
 * post_gradient takes it, with the gradient. */
inline bool post_segment(const real *s, __constant const real *nodes, __constant const real *weights,
                         __global const real4 *tf, const Shading *P, const real radius, const real weight,
                         real *budget, real *u, real *c, OneInterval *O, bool *one, real4 *r, int *midpoints,
                         int *evals)
{
    *r = (real4)(0);
    if (!segment_scalar(s, nodes, tf, u, c))
        return true;
    *one = one_interval(u, c, weights, tf, radius, O);
    real3 e;
    if (!(*one && SHADING && (interval_unlit(O, c, P, weight, budget, &e)
                               || interval_midpoint(O, P, weight, budget, &e))))
        return false;
    *r = (real4)(e, O->depth);
    *midpoints += 1;
    *evals += 9;
    return true;
}

/* The rest of post_segment's segments, from the gradient of s at the lanes (fine units): inside one interval and
 * where the shading does not turn, Simpson on the nine samples when that is within tol; else cut where u crosses a
 * breakpoint or the shading turns, and finer panels (classified_segment) */
inline real4 post_gradient(const OneInterval *O, const bool one, real *c, const real *u, const realv gx,
                           const realv gy, const realv gz, const real radius, __constant const real *nodes,
                           __constant const real *weights, __global const real4 *tf, const Shading *P,
                           const real tol, int *evals, int *flags)
{
    real3 e, g[NG];
    if (one && interval_simpson(O, gx, gy, gz, P, nodes, tol, &e, evals))
        return (real4)(e, O->depth);
    lane_series(gx, gy, gz, nodes, g);
    real lx[16], ly[16], lz[16];
    vstore16(gx, 0, lx);
    vstore16(gy, 0, ly);
    vstore16(gz, 0, lz);
    return classified_segment(c, u, lx, ly, lz, g, radius, nodes, weights, tf, P, tol, evals, flags);
}
#endif
