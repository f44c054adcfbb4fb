/* tf_table.h: the transfer function's table, searched in O(log K) whatever its points (docs/raytracing.md §10).
 *
 * Rows (real4, clwave/raytrace/classified.py tf_table): row 0 (scale, shift, K, 0); rows p = 1..K the breakpoints,
 * (u_p, alpha at u_p, max node p, 0), u_p non-decreasing; then per interval k = 0..K (u below u_1, between u_k and
 * u_{k+1}, above u_K) three rows (u_ref, alpha_ref, alpha_slope, 0), (rgb_ref, 0), (rgb_slope, 0).  The opacities at
 * the breakpoints are the leaves K..2K-1 of a max tree whose nodes 1..K-1 are the rows' z (node i: the larger of
 * nodes 2i and 2i + 1), so the largest over a run of breakpoints takes log K steps.
 * Needs `real`, `real4` (types.h, or float in scalar.cl); the table in __global: it can outgrow a constant buffer. */
#ifndef CLW_TF_TABLE_H
#define CLW_TF_TABLE_H

/* how many breakpoints are below v (`at` false) or at most v (`at` true): a binary search */
inline int tf_count(__global const real4 *tf, const int K, const real v, const bool at)
{
    int first = 0, n = K;
    while (n > 0) {
        const int mid = n / 2;
        const real x = tf[1 + first + mid].x;
        if (at ? x <= v : x < v) {
            first += mid + 1;
            n -= mid + 1;
        } else
            n = mid;
    }
    return first;
}

/* the interval of u: how many breakpoints are <= u */
inline int tf_interval(__global const real4 *tf, const int K, const real u)
{
    return tf_count(tf, K, u, true);
}

/* the transfer function's opacity at u */
inline real tf_alpha(__global const real4 *tf, const int K, const real u)
{
    const real4 line = tf[1 + K + 3 * tf_interval(tf, K, u)];
    return fmax(line.y + line.z * (u - line.x), (real)0);
}

/* the largest opacity over [lo, hi]: at its ends or at a breakpoint inside (the function is piecewise linear) */
inline real tf_peak(__global const real4 *tf, const int K, const real lo, const real hi)
{
    real m = fmax(tf_alpha(tf, K, lo), tf_alpha(tf, K, hi));
    for (int l = K + tf_count(tf, K, lo, false), r = K + tf_count(tf, K, hi, true); l < r; l /= 2, r /= 2) {
        if (l & 1) {
            m = fmax(m, l >= K ? tf[1 + l - K].y : tf[l].z);
            l += 1;
        }
        if (r & 1) {
            r -= 1;
            m = fmax(m, r >= K ? tf[1 + r - K].y : tf[r].z);
        }
    }
    return m;
}
#endif
