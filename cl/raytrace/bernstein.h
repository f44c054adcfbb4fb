/* bernstein.h: where a polynomial on a segment changes sign, from its Bernstein coefficients (post-classification,
 * classify.h, docs/raytracing.md §10): they bound it on a span (convex hull), and by Descartes' rule for the
 * Bernstein basis a span whose coefficients change sign once holds exactly one root of odd multiplicity, found by
 * bisection on the coefficients (de Casteljau); other spans are halved.  Build: nodes carry, after the sample
 * tables, the (NS, NS) matrix from the samples to the Bernstein coefficients on [-1, 1], then the (9, 9) one from
 * the gradient lanes 0..8 to theirs (clwave/raytrace/classified.py post_nodes). */
#ifndef CLW_BERNSTEIN_H
#define CLW_BERNSTEIN_H
#include "raytrace/types.h"

#define POST_BISECTIONS 40 /* bisection steps for a root (stops earlier at the arithmetic's resolution) */
#define SHADE_CUTS 8       /* cuts at most per piece where grad s . L changes sign (more: Simpson alone) */
#define SHADE_DEPTH 10     /* spans of grad s . L are halved at most this often in the search for its roots */
#define BERNSTEIN9 (NS + 2 * NS * NS + 81) /* where the lanes-to-Bernstein matrix of degree 8 starts in nodes */

/* the coefficients of the two parts [0, tau] (left) and [tau, 1] (right) of a Bernstein polynomial of degree
 * n - 1 on its span, c its coefficients (de Casteljau); left[n - 1] = right[0] is its value at tau */
inline void bernstein_split_n(const real *c, const int n, const real tau, real *left, real *right)
{
    real w[NS];
    for (int i = 0; i < n; i++)
        w[i] = c[i];
    left[0] = c[0];
    right[n - 1] = c[n - 1];
    for (int r = 1; r < n; r++) {
        for (int i = 0; i < n - r; i++)
            w[i] = (1 - tau) * w[i] + tau * w[i + 1];
        left[r] = w[0];
        right[n - 1 - r] = w[n - 1 - r];
    }
}

inline void bernstein_split(const real *c, const real tau, real *left, real *right)
{
    bernstein_split_n(c, NS, tau, left, right);
}

/* The Bernstein coefficients c of the degree-8 polynomial whose values at the gradient lanes' points are v;
 * returns their rounding, 64 eps times the largest */
inline real bernstein9(const real *v, __constant const real *nodes, real *c)
{
    real big = 0;
    for (int k = 0; k < 9; k++) {
        real sum = 0;
        for (int j = 0; j < 9; j++)
            sum += nodes[BERNSTEIN9 + 9 * k + j] * v[j];
        c[k] = sum;
        big = fmax(big, fabs(sum));
    }
    return 64 * REAL_EPSILON * big;
}

/* sign changes among the coefficients c[0..8] clear of eps */
inline int coefficient_sign_changes(const real *c, const real eps)
{
    int changes = 0, last = 0;
    for (int i = 0; i < 9; i++)
        if (fabs(c[i]) > eps) {
            changes += c[i] * c[last] < 0;
            last = i;
        }
    return changes;
}

/* Where the degree-8 polynomial p changes sign inside [a, b], from its values v at a + (b - a)(xi_j + 1) / 2
 * (xi_j: the gradient lanes' points): merged in increasing order into cuts[0..*n), at most SHADE_CUTS.  Its
 * Bernstein coefficients bound it on a span: no sign change there, no root; one, exactly one root of odd
 * multiplicity (Descartes' rule), found by bisection on the coefficients (de Casteljau); more, the span is
 * halved, at most SHADE_DEPTH times (a span still holding several is left to Simpson).  Roots within the
 * coefficients' rounding of 0 at an end are ignored: no sign change there that Simpson could miss. */
inline void sign_changes(const real *v, __constant const real *nodes, const real a, const real b, real *cuts,
                         int *n)
{
    real c[9];
    const real eps = bernstein9(v, nodes, c);
    real stack_c[SHADE_DEPTH][9], stack_ab[SHADE_DEPTH][2];
    int stack_depth[SHADE_DEPTH], top = 0, depth = 0;
    real l = a, r = b;
    while (true) {
        const int changes = coefficient_sign_changes(c, eps);
        if (changes == 1 || (changes > 1 && depth < SHADE_DEPTH)) {
            real x = (l + r) / 2, left[9], right[9];
            if (changes == 1) { /* the root, by bisection on the span's coefficients */
                real lo = 0, hi = 1, tau = 0.5;
                for (int it = 0; it < POST_BISECTIONS && lo < tau && tau < hi; it++) {
                    bernstein_split_n(c, 9, tau, left, right);
                    if (right[0] * c[0] > 0)
                        lo = tau;
                    else
                        hi = tau;
                    tau = (lo + hi) / 2;
                }
                x = l + (r - l) * tau;
                if (*n < SHADE_CUTS && x > a && x < b && (*n == 0 || x != cuts[*n - 1])) {
                    int i = *n;
                    for (; i > 0 && cuts[i - 1] > x; i--)
                        cuts[i] = cuts[i - 1];
                    cuts[i] = x;
                    *n += 1;
                }
            } else { /* halved: the right part waits */
                bernstein_split_n(c, 9, (real)0.5, left, stack_c[top]);
                stack_ab[top][0] = x;
                stack_ab[top][1] = r;
                stack_depth[top++] = ++depth;
                for (int i = 0; i < 9; i++)
                    c[i] = left[i];
                r = x;
                continue;
            }
        }
        if (top == 0)
            return;
        top -= 1;
        for (int i = 0; i < 9; i++)
            c[i] = stack_c[top][i];
        l = stack_ab[top][0];
        r = stack_ab[top][1];
        depth = stack_depth[top];
    }
}

/* Whether u - v has exactly one root inside the span of Bernstein coefficients c: the coefficients change sign
 * once (Descartes' rule for the Bernstein basis), the ends clear of v by more than eps */
inline bool one_crossing(const real *c, const real v, const real eps)
{
    int changes = 0;
    for (int i = 1; i < NS; i++)
        changes += (c[i - 1] - v) * (c[i] - v) < 0;
    return changes == 1 && fabs(c[0] - v) > eps && fabs(c[NS - 1] - v) > eps;
}
#endif
