/* cl/raytrace/field_wavelet.h: the wavelet-space path of cl/raytrace/raytrace.cl (paper §3.2-3.3, docs/model.md §4).
 *
 * The field is summed directly from the kept coefficients, with no inverse transform: each ray
 * keeps an active list of the basis functions whose supports contain the current segment, a
 * binary heap ordered by the leaving parameter t_A (paper eq. 25-27 with the corrected lattice
 * step 2^m / dir, docs/errata.md §2).  Per band, the relevant indices at a point are the exact range of
 * docs/model.md §4 (S per axis); when the range moves between segments, the new indices (at most three
 * slabs of the index box) are looked up in the dense bands and the non-zero ones pushed; entries
 * whose t_A has passed are popped.  All of a band's support planes are knot planes of the fine
 * lattice, so the active set is constant on each segment.  When the heap is full, the ray falls
 * back to visiting every relevant index per segment (flag bit 2): slower, never wrong.
 *
 * Build: -DCLW_BANDS (number of bands), -DCLW_ACTIVE (entries per ray's heap), -DCLW_TRACE=S (tests).
 * Bands (host: clwave/raytrace/tracer.py, RayTracer._bands):
 *   coef   (sum of band sizes,) float4: dense bands, c 2^{-3m/2} at its channels' RGBA places
 *   info   (CLW_BANDS,) int4: (level m, psi axes as bits x | y << 1 | z << 2, order j, offset)
 *   shape  (CLW_BANDS,) int4: (nx, ny, nz)
 *   band_lo (CLW_BANDS,) float4: lower support corner of k = 0, grid-0 fine coordinates; w = 2^m
 *   poly   rows of 6 monomial coefficients (clwave.model.bspline.piece_polynomials): N_j(s + r) at
 *          PHI_ROW[j] + r, psi((s + c) / 2) at PSI_ROW[j] + c, for s in [0, 1)
 *   trace  CLW_TRACE builds: per ray and for its first CLW_TRACE segments, the active set as
 *          (count, sum of (id + 1), sum of (id + 1)^2 (both mod 2^32), t_mid as float bits),
 *          id = index into coef, for the test against the brute-force set of supports */

#ifndef CLW_FIELD_H
#define CLW_FIELD_H
#include "raytrace/types.h"

/* the first row of order j's pieces (j = 1, 2, 3, 4, 6): phi's j rows each, then psi's 2 (2j - 1) */
constant int PHI_ROW[7] = {0, 0, 1, 3, 6, 0, 10};
constant int PSI_ROW[7] = {0, 16, 18, 24, 34, 0, 48};

#define FIELD_PARAMS __global const float4 *coef, __constant const int4 *info, __constant const int4 *shape, \
                     __constant const float4 *band_lo, __constant const real *poly, __global int4 *trace
typedef struct {
    __global const float4 *coef;
    __constant const int4 *info, *shape;
    __constant const float4 *lo;
    __constant const real *poly;
    __global int4 *trace;
} Field;
#define FIELD_INIT {coef, info, shape, band_lo, poly, trace}
#define FIELD_BRICK 0 /* one lattice everywhere: the fine one */
inline real4 field_lattice(const Field G, const real3 x, void *A) { return (real4)(0, 0, 0, CLW_LATTICE); }

typedef struct {
    real t;     /* t_A: where the ray leaves the support */
    int band;
    int id;     /* index into coef */
} Entry;

typedef struct {
    Entry heap[CLW_ACTIVE];
    int n;
    bool brute;                                   /* the heap overflowed: visit every index */
    int4 box_lo[CLW_BANDS], box_hi[CLW_BANDS];    /* relevant index box at the last segment */
    real3 X0, D;                                  /* the ray, grid-0 fine coordinates */
    size_t pix;
    int traced;
} Active;

inline void active_init(Active *A, const Field G, const size_t pix, const real3 X0, const real3 D)
{
    A->n = 0;
    A->brute = false;
    for (int b = 0; b < CLW_BANDS; b++) {
        A->box_lo[b] = (int4)(0);
        A->box_hi[b] = (int4)(-1);
    }
    A->X0 = X0;
    A->D = D;
    A->pix = pix;
    A->traced = 0;
}

inline int active_flags(const Active *A) { return A->brute ? 4 : 0; }

inline int support_length(const int j, const int psi) { return psi ? 2 * j - 1 : j; }

/* the relevant indices of band b at x (docs/model.md §4), clipped to the band: empty when hi < lo */
inline void index_box(const Field G, const int b, const real3 x, int4 *klo, int4 *khi)
{
    const int4 inf = G.info[b], n = G.shape[b];
    const real4 o = to_real4(G.lo[b]);
    const real xs[3] = {x.x, x.y, x.z}, os[3] = {o.x, o.y, o.z};
    const int ns[3] = {n.x, n.y, n.z};
    int lo3[3], hi3[3];
    for (int a = 0; a < 3; a++) {
        const int top = (int)floor((xs[a] - os[a]) / o.w);
        lo3[a] = max(top - support_length(inf.z, (inf.y >> a) & 1) + 1, 0);
        hi3[a] = min(top, ns[a] - 1);
    }
    *klo = (int4)(lo3[0], lo3[1], lo3[2], 0);
    *khi = (int4)(hi3[0], hi3[1], hi3[2], 0);
}

/* t_A of index k of band b: the nearest leaving plane, prototype's plus k 2^m / dir (eq. 26) */
inline real leaving(const Field G, const Active *A, const int b, const int4 k)
{
    const int4 inf = G.info[b];
    const real4 o = to_real4(G.lo[b]);
    const real os[3] = {o.x, o.y, o.z}, x0[3] = {A->X0.x, A->X0.y, A->X0.z}, d[3] = {A->D.x, A->D.y, A->D.z};
    const int ks[3] = {k.x, k.y, k.z};
    real t = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (d[a] == 0)
            continue;
        const real edge = os[a] + (d[a] > 0 ? support_length(inf.z, (inf.y >> a) & 1) : 0) * o.w;
        t = fmin(t, (edge - x0[a]) / d[a] + ks[a] * (o.w / d[a]));
    }
    return t;
}

inline bool heap_push(Active *A, const Entry e)
{
    if (A->n == CLW_ACTIVE)
        return false;
    int i = A->n++;
    while (i > 0 && A->heap[(i - 1) / 2].t > e.t) {
        A->heap[i] = A->heap[(i - 1) / 2];
        i = (i - 1) / 2;
    }
    A->heap[i] = e;
    return true;
}

inline void heap_pop(Active *A)
{
    const Entry last = A->heap[--A->n];
    int i = 0;
    for (;;) {
        int c = 2 * i + 1;
        if (c >= A->n)
            break;
        if (c + 1 < A->n && A->heap[c + 1].t < A->heap[c].t)
            c++;
        if (A->heap[c].t >= last.t)
            break;
        A->heap[i] = A->heap[c];
        i = c;
    }
    if (A->n > 0)
        A->heap[i] = last;
}

inline real horner(__constant const real *p, const real s)
{
    return ((((p[5] * s + p[4]) * s + p[3]) * s + p[2]) * s + p[1]) * s + p[0];
}
inline real horner_d(__constant const real *p, const real s)
{
    return (((5 * p[5] * s + 4 * p[4]) * s + 3 * p[3]) * s + 2 * p[2]) * s + p[1];
}

typedef struct {
    uint count, sum, sum2;
} Census;

/* add basis function `id` of band b (support corner of index k) to the segment's samples */
inline void add_basis(const Field G, const int b, const int id, const int4 k, const real3 xm, const real radius,
                      const real3 D, __constant const real *nodes, real4 *fq, real3 *fg, Census *census)
{
    const int4 inf = G.info[b];
    const real4 o = to_real4(G.lo[b]);
    const real4 c = to_real4(G.coef[id]);
    const real inv = 1 / o.w;
    const real xs[3] = {xm.x, xm.y, xm.z}, ds[3] = {D.x, D.y, D.z}, os[3] = {o.x, o.y, o.z};
    const int ks[3] = {k.x, k.y, k.z};
    __constant const real *rows[3];
    real at[3], slope[3], chain[3];
    for (int a = 0; a < 3; a++) {
        const int psi = (inf.y >> a) & 1;
        const real u = ((xs[a] - os[a]) * inv - ks[a]) * (psi ? 2 : 1);  /* local coordinate at the midpoint */
        const int cells = psi ? 2 * (2 * inf.z - 1) : inf.z;
        const int piece = clamp((int)floor(u), 0, cells - 1);             /* one polynomial for the segment */
        rows[a] = G.poly + 6 * ((psi ? PSI_ROW[inf.z] : PHI_ROW[inf.z]) + piece);
        chain[a] = inv * (psi ? 2 : 1);
        at[a] = u - piece;
        slope[a] = radius * ds[a] * chain[a];
    }
    for (int s = 0; s < NS; s++) {
        const real xi = nodes[s];
        const real px = at[0] + slope[0] * xi, py = at[1] + slope[1] * xi, pz = at[2] + slope[2] * xi;
        const real vx = horner(rows[0], px), vy = horner(rows[1], py), vz = horner(rows[2], pz);
        fq[s] += c * (vx * vy * vz);
#ifdef CLW_SHADE
        fg[s] += c.w * (real3)(horner_d(rows[0], px) * chain[0] * vy * vz, vx * horner_d(rows[1], py) * chain[1] * vz,
                               vx * vy * horner_d(rows[2], pz) * chain[2]);
#endif
    }
#ifdef CLW_TRACE
    const uint u1 = (uint)id + 1;
    census->count += 1;
    census->sum += u1;
    census->sum2 += u1 * u1;
#endif
}

inline int flat_index(const Field G, const int b, const int4 k)
{
    const int4 n = G.shape[b];
    return G.info[b].w + (k.z * n.y + k.y) * n.x + k.x;
}

inline bool nonzero(const float4 c) { return c.x != 0 || c.y != 0 || c.z != 0 || c.w != 0; }

/* push the non-zero coefficients of band b in the index box [lo, hi]; false when the heap is full */
inline bool push_box(const Field G, Active *A, const int b, const int4 lo, const int4 hi)
{
    for (int kz = lo.z; kz <= hi.z; kz++)
        for (int ky = lo.y; ky <= hi.y; ky++)
            for (int kx = lo.x; kx <= hi.x; kx++) {
                const int4 k = (int4)(kx, ky, kz, 0);
                const int id = flat_index(G, b, k);
                if (nonzero(G.coef[id])) {
                    const Entry e = {leaving(G, A, b, k), b, id};
                    if (!heap_push(A, e))
                        return false;
                }
            }
    return true;
}

/* one axis of box_new minus box_old: the new interval (dlo, dhi) and the kept one (ilo, ihi) */
inline void split_interval(const int nlo, const int nhi, const int olo, const int ohi, int *dlo, int *dhi,
                           int *ilo, int *ihi)
{
    if (ohi < olo || nhi < olo || nlo > ohi) { /* nothing kept */
        *dlo = nlo; *dhi = nhi; *ilo = 0; *ihi = -1;
    } else if (nhi > ohi) {                    /* moved up */
        *dlo = ohi + 1; *dhi = nhi; *ilo = nlo; *ihi = ohi;
    } else if (nlo < olo) {                    /* moved down */
        *dlo = nlo; *dhi = olo - 1; *ilo = olo; *ihi = nhi;
    } else {
        *dlo = 0; *dhi = -1; *ilo = nlo; *ihi = nhi;
    }
}

/* bring the active list to the segment around x_mid: pop what was left, push what was entered */
inline void update_active(const Field G, Active *A, const real t_mid, const real3 xm)
{
    while (A->n > 0 && A->heap[0].t <= t_mid)
        heap_pop(A);
    for (int b = 0; b < CLW_BANDS && !A->brute; b++) {
        int4 nlo, nhi;
        index_box(G, b, xm, &nlo, &nhi);
        const int4 olo = A->box_lo[b], ohi = A->box_hi[b];
        A->box_lo[b] = nlo;
        A->box_hi[b] = nhi;
        if (any(nhi < nlo))
            continue;
        const bool old_empty = any(ohi < olo);
        int dl[3], dh[3], il[3], ih[3];
        const int nl[3] = {nlo.x, nlo.y, nlo.z}, nh[3] = {nhi.x, nhi.y, nhi.z};
        const int ol[3] = {olo.x, olo.y, olo.z}, oh[3] = {ohi.x, ohi.y, ohi.z};
        for (int a = 0; a < 3; a++)
            split_interval(nl[a], nh[a], old_empty ? 0 : ol[a], old_empty ? -1 : oh[a], &dl[a], &dh[a], &il[a], &ih[a]);
        /* new = D_x x N_y x N_z  +  I_x x D_y x N_z  +  I_x x I_y x D_z */
        const bool ok = push_box(G, A, b, (int4)(dl[0], nl[1], nl[2], 0), (int4)(dh[0], nh[1], nh[2], 0)) &&
                        push_box(G, A, b, (int4)(il[0], dl[1], nl[2], 0), (int4)(ih[0], dh[1], nh[2], 0)) &&
                        push_box(G, A, b, (int4)(il[0], il[1], dl[2], 0), (int4)(ih[0], ih[1], dh[2], 0));
        if (!ok)
            A->brute = true;
    }
}

inline int4 index_of(const Field G, const int b, const int id)
{
    const int4 n = G.shape[b];
    const int f = id - G.info[b].w;
    return (int4)(f % n.x, (f / n.x) % n.y, f / (n.x * n.y), 0);
}

/* What sample_gradient needs: alpha's gradient at the sample points, summed with the field */
typedef struct {
    real3 fg[NS];
} Basis;

/* The field at every sample point (`fresh` is for the B-spline path), and alpha's gradient */
inline void sample_segment(const Field G, Active *A, const real t_mid, const real3 xm, const real radius,
                           const real3 D, __constant const real *nodes, const bool fresh, real4 *fq,
                           Basis *basis)
{
    real3 *fg = basis[0].fg;
    for (int s = 0; s < NS; s++) {
        fq[s] = (real4)(0);
        fg[s] = (real3)(0);
    }
    Census census = {0, 0, 0};
    if (!A->brute)
        update_active(G, A, t_mid, xm);
    if (!A->brute) {
        for (int i = 0; i < A->n; i++)
            add_basis(G, A->heap[i].band, A->heap[i].id, index_of(G, A->heap[i].band, A->heap[i].id), xm, radius,
                      D, nodes, fq, fg, &census);
    } else { /* overflow fallback: every relevant index of every band */
        for (int b = 0; b < CLW_BANDS; b++) {
            int4 lo, hi;
            index_box(G, b, xm, &lo, &hi);
            for (int kz = lo.z; kz <= hi.z; kz++)
                for (int ky = lo.y; ky <= hi.y; ky++)
                    for (int kx = lo.x; kx <= hi.x; kx++) {
                        const int4 k = (int4)(kx, ky, kz, 0);
                        const int id = flat_index(G, b, k);
                        if (nonzero(G.coef[id]))
                            add_basis(G, b, id, k, xm, radius, D, nodes, fq, fg, &census);
                    }
        }
    }
#ifdef CLW_TRACE
    if (A->traced < CLW_TRACE) {
        const float tm = (float)t_mid;
        G.trace[A->pix * CLW_TRACE + A->traced++] = (int4)((int)census.count, (int)census.sum, (int)census.sum2,
                                                             as_int(tm));
    }
#endif
}

/* alpha's gradient came with the field: into lanes (all of them; `all` is for the B-spline path) */
inline void sample_gradient(const Basis *basis, const bool all, realv *gx, realv *gy, realv *gz)
{
    real lx[16] = {0}, ly[16] = {0}, lz[16] = {0};
    for (int s = 0; s < NS; s++) {
        lx[s] = basis[0].fg[s].x;
        ly[s] = basis[0].fg[s].y;
        lz[s] = basis[0].fg[s].z;
    }
    *gx = vload16(0, lx);
    *gy = vload16(0, ly);
    *gz = vload16(0, lz);
}
#endif
