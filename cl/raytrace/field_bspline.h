/* field_bspline.h: the field from the brick-sparse multiresolution B-spline pool
 * (clwave/raytrace/bricks.py): each sample reads j^3 lattice coefficients per channel group, on the
 * lattice of the brick holding the segment.  The interface every field backend provides to
 * cl/raytrace/raytrace.cl: FIELD_PARAMS and FIELD_INIT (the kernel arguments and the Field struct made
 * of them), field_lattice (the knot planes around a point) and FIELD_BRICK (the cells between the
 * planes where that can change; 0: never), Active with active_init and active_flags (per-ray state),
 * Basis with segment_basis, sample_segment and sample_gradient. */
#ifndef CLW_FIELD_H
#define CLW_FIELD_H
#include "raytrace/types.h"
#include "raytrace/scalar_pool.h"

/* ---- B-spline path: bricks of lattice coefficients (clwave/raytrace/bricks.py) ---- */
/* A coefficient of the pool: float4 (channels in their slots), or for a scalar model a whole number q packed in
 * the pool's bytes, the coefficient offset + step q with its slot's Quant in quant (CLW_SCALAR_POOL, scalar_pool.h,
 * clwave/raytrace/classified.py, docs/raytracing.md §10: sample_segment decodes the segment's cell once, into
 * Basis.q, and sums q); COEF4 reads a float4 as four channels, GRADIENT_LANE names the channel whose gradient
 * shades: alpha, or the scalar post-classified (CLW_POST, classify.h).  CORNER is what a Basis reads its cell's
 * coefficients from (the pool at the cell's last coefficient, or the decoded q) and CORNER_COEF(c, sy, sz, j, rz,
 * ry, rx) the coefficient rz planes, ry rows and rx places before that last one. */
#ifdef CLW_POST
#define GRADIENT_LANE x
#else
#define GRADIENT_LANE w
#endif
#ifdef CLW_SCALAR_POOL
typedef uchar coef_t;
#define COEF4(c) ((real4)((real)(c), 0, 0, 0))
#define CORNER(B) ((B)->q)
#define CORNER_COEF(c, sy, sz, j, rz, ry, rx) ((c)[((rz) * (j) + (ry)) * (j) + (rx)])
typedef const real *corner_t;
#else
typedef float4 coef_t;
#define COEF4(c) to_real4(c)
#define CORNER(B) ((B)->corner)
#define CORNER_COEF(c, sy, sz, j, rz, ry, rx) ((c)[-(rz) * (sz) - (ry) * (sy) - (rx)].GRADIENT_LANE)
typedef __global const coef_t *corner_t;
#endif
#define FIELD_PARAMS __global const coef_t *coef, __global const int *pages, const int4 page_origin, \
                     const int4 page_shape, __global const float4 *frames, __global const int4 *boxes, \
                     __global const float4 *lattices, __global const int4 *mixes, __global const uchar *pieces, \
                     __global const Quant *quant, __global const uchar *joins
typedef struct {
    __global const coef_t *coef;
    __global const int *pages;
    int4 page_origin, page_shape;
    __global const float4 *frames;
    __global const int4 *boxes;
    __global const float4 *lattices;
    __global const int4 *mixes;  /* per slot: a mixed brick's coarse slot (-1: not mixed), first piece, pieces per axis */
    __global const uchar *pieces; /* per piece of a mixed brick: 1 to march it on the coarse slot */
    __global const Quant *quant; /* per slot of a scalar pool: where its q lie, and their offset and step */
    __global const uchar *joins; /* per brick of the page table: its coarse lattice's spacing (not mixed), else 0 */
} Field;
#define FIELD_INIT {coef, pages, page_origin, page_shape, frames, boxes, lattices, mixes, pieces, quant, joins}
#define FIELD_BRICK CLW_SUPER_CELLS /* a brick is a superblock */
/* The brick the ray is in (field_lattice sets it): the slot its segments read, and in a mixed brick
 * (clwave/raytrace/pieces.py, docs/raytracing.md §3) its fine and coarse slots and their knot lattices, the
 * lattice of its pieces (parts of the coarse cells, `piece_lat.w` fine cells a side; `parts` per coarse cell and
 * axis, `n` per axis in the brick) and its piece flags (field_piece reads a piece's, field_run picks a slot) */
typedef struct {
    int slot, fine, coarse, table, n, parts;
    real4 fine_lat, coarse_lat, piece_lat;
} Active;
#define FIELD_MIXES
inline void active_init(Active *A, const Field G, const size_t pix, const real3 X0, const real3 D)
{
    A->slot = -1;
    A->coarse = -1;
}
inline int active_flags(const Active *A) { return 0; }

/* the pool slot of the brick holding grid-0 point x, -1 where there is none */
inline int brick_slot(const Field G, const real3 x)
{
    const int4 k = convert_int4((real4)(floor(x / FIELD_BRICK), 0)) - G.page_origin;
    if (k.x < 0 || k.y < 0 || k.z < 0 || k.x >= G.page_shape.x || k.y >= G.page_shape.y || k.z >= G.page_shape.z)
        return -1;
    return G.pages[((size_t)k.z * G.page_shape.y + k.y) * G.page_shape.x + k.x];
}

/* the knot planes of the brick holding x, which the ray has entered: origin (x, y, z) and spacing */
inline real4 field_lattice(const Field G, const real3 x, Active *A)
{
    A->slot = A->fine = brick_slot(G, x);
    A->coarse = -1;
    if (A->slot < 0)
        return (real4)(0, 0, 0, CLW_LATTICE);
    const int4 m = G.mixes[A->slot];
    /* a brick mixed with itself (unclamped, alpha may dip below 0): its fine pieces on the fine lattice */
    A->fine_lat = m.x == A->slot ? (real4)(0, 0, 0, CLW_LATTICE) : to_real4(G.lattices[A->slot]);
    if (m.x >= 0) {
        A->coarse = m.x;
        A->table = m.y;
        A->n = m.z;
        A->coarse_lat = to_real4(G.lattices[m.x]);
        A->piece_lat = (real4)(A->coarse_lat.xyz, (real)m.w);
        A->parts = (int)(A->coarse_lat.w / m.w);
    }
    return A->fine_lat;
}

/* whether the brick holding x goes on with the knot lattice lat of the one the ray is in, so that a segment may cross
 * the face between them (docs/raytracing.md §3, "segments per brick"): a brick that is not mixed, on the same lattice
 * (a coarse one: the caller's test; `joins` says it for every brick, whichever slots a pass holds).  Bricks of one
 * level share its lattice and hold the same coefficients where their boxes meet, and a segment lies in one lattice
 * cell, whose coefficients are all in the box of each brick it touches: the brick the segment starts in gives the
 * polynomial of its whole cell. */
inline bool field_continues(const Field G, const real3 x, const real4 lat)
{
    const int4 k = convert_int4((real4)(floor(x / FIELD_BRICK), 0)) - G.page_origin;
    if (k.x < 0 || k.y < 0 || k.z < 0 || k.x >= G.page_shape.x || k.y >= G.page_shape.y || k.z >= G.page_shape.z)
        return false;
    return G.joins[((size_t)k.z * G.page_shape.y + k.y) * G.page_shape.x + k.x] == lat.w;
}

/* whether the ray is in a mixed brick */
inline bool field_mixed(const Active *A) { return A->coarse >= 0; }

/* In a mixed brick: the piece holding x, by its (x, y, z) index among the brick's pieces, which start with the first
 * coarse cell holding one of its cells; the march steps it from piece to piece */
inline int3 piece_index(const real3 x, const Active *A)
{
    const real3 o = A->coarse_lat.xyz, first = floor(x / FIELD_BRICK) * FIELD_BRICK;
    return convert_int3(floor((x - o) / A->piece_lat.w)) -
           convert_int3(floor((first - o) / A->coarse_lat.w)) * A->parts;
}

/* the flag of piece k (PIECE_FINE, PIECE_COARSE: marched on that slot; PIECE_EMPTY: no content voxel reaches it, the
 * clamped field is 0 there); k is clamped to the brick's pieces */
#define PIECE_FINE 0
#define PIECE_COARSE 1
#define PIECE_EMPTY 2
inline int field_piece(const Field G, const int3 k, const Active *A)
{
    const int3 c = clamp(k, 0, A->n - 1);
    return G.pieces[A->table + (c.z * A->n + c.y) * A->n + c.x];
}

/* In a mixed brick: a run of pieces with one flag, read from the coarse slot or from the fine one; its knot planes */
inline real4 field_run(Active *A, const int flag)
{
    A->slot = flag == PIECE_COARSE ? A->coarse : A->fine;
    return flag == PIECE_COARSE ? A->coarse_lat : A->fine_lat;
}

/* w[r] = N_j(u + r) (BSPLINE_WEIGHTS) and dw[r] = N_j'(u + r) (BSPLINE_DERIVATIVES), r = 0..j-1:
 * the weight of coefficient c - r in cell c at u = x - c (docs/model.md §1), per lane of TYPE.
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
        } else if (j == 4) {                                                                      \
            w[0] = u * u * u * sixth; w[1] = ((-3 * u + 3) * u * u + 3 * u + 1) * sixth;          \
            w[2] = ((3 * u - 6) * u * u + 4) * sixth; w[3] = s * s * s * sixth;                   \
        } else {                                                                                  \
            const real c = (real)1 / 120;                                                         \
            const TYPE u2 = u * u, s2 = s * s;                                                    \
            w[0] = u2 * u2 * u * c; w[1] = (1 + u * (5 + u * (10 + u * (10 + u * (5 - 5 * u))))) * c; \
            w[2] = (26 + u * (50 + u * (20 + u * (-20 + u * (-20 + 10 * u))))) * c;               \
            w[3] = (66 + u2 * (-60 + u2 * (30 - 10 * u))) * c;                                    \
            w[4] = (26 + u * (-50 + u * (20 + u * (20 + u * (-20 + 5 * u))))) * c; w[5] = s2 * s2 * s * c; \
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
        } else if (j == 6) {                                                                      \
            const real c = (real)1 / 120;                                                         \
            const TYPE u2 = u * u, s2 = (1 - u) * (1 - u);                                        \
            dw[0] = 5 * u2 * u2 * c; dw[1] = (5 + u * (20 + u * (30 + u * (20 - 25 * u)))) * c;   \
            dw[2] = (50 + u * (40 + u * (-60 + u * (-80 + 50 * u)))) * c;                         \
            dw[3] = u * (-120 + u2 * (120 - 50 * u)) * c;                                         \
            dw[4] = (-50 + u * (40 + u * (60 + u * (-80 + 25 * u)))) * c; dw[5] = -5 * s2 * s2 * c; \
        }                                                                                         \
    }
/* lanes 8..11 (real4), or 8..15 (real8) when NS = 16 */
#if NS > 12
typedef real8 realt;
#else
typedef real4 realt;
#endif
BSPLINE_WEIGHTS(real8, bspline_weights8)
BSPLINE_WEIGHTS(realt, bspline_weights_tail)
BSPLINE_DERIVATIVES(real8, bspline_derivatives8)
BSPLINE_DERIVATIVES(realt, bspline_derivatives_tail)

/* One group's part of the field at every sample at once: the j^3 coefficients ending at `corner`
 * (the segment's cell), summed separably (along x per (y, z) row, then along y per z plane, then
 * along z).  The lanes are fq's memory order, sample-major: samples 0..3 in v[0], 4..7 in v[1]
 * (four channels each), 8 and 9 in f8 (only when `tail`), so each coefficient is read once per
 * segment and feeds 40 lanes in three vector FMAs (with 16 samples, order 6, a second call sums samples
 * 8..15 the way of 0..7).  w[a][r][h] and w8[a][r] are the weights spread to those lanes; the sums are
 * added to f, f8.  Always inlined with a literal order j and `tail`, so the loops unroll. */
__attribute__((always_inline)) inline void group_field(__global const coef_t *corner, const int sy, const int sz,
                                                       const int j, const bool tail, real16 w[3][MAX_ORDER][2],
                                                       real8 w8[3][MAX_ORDER], real16 *f, real8 *f8)
{
    real16 v0 = 0, v1 = 0;
    real8 v8 = 0;
#pragma unroll
    for (int rz = 0; rz < j; rz++) {
        real16 plane0 = 0, plane1 = 0;
        real8 plane8 = 0;
#pragma unroll
        for (int ry = 0; ry < j; ry++) {
            __global const coef_t *row = corner - rz * sz - ry * sy;
            real16 line0 = 0, line1 = 0;
            real8 line8 = 0;
#pragma unroll
            for (int rx = 0; rx < j; rx++) {
                const real4 c = COEF4(row[-rx]);
                const real16 c16 = (real16)(c, c, c, c);
                line0 = fma(c16, w[0][rx][0], line0);
                line1 = fma(c16, w[0][rx][1], line1);
                if (tail)
                    line8 = fma(c16.lo, w8[0][rx], line8);
            }
            plane0 = fma(line0, w[1][ry][0], plane0);
            plane1 = fma(line1, w[1][ry][1], plane1);
            if (tail)
                plane8 = fma(line8, w8[1][ry], plane8);
        }
        v0 = fma(plane0, w[2][rz][0], v0);
        v1 = fma(plane1, w[2][rz][1], v1);
        if (tail)
            v8 = fma(plane8, w8[2][rz], v8);
    }
    f[0] += v0;
    f[1] += v1;
    *f8 += v8;
}

/* The alpha group's part of alpha's fine gradient at all lanes of TYPE at once: the same
 * separable sum as group_field on the alpha channel (CORNER_COEF), with the derivative weights d? */
#define GROUP_GRADIENT(TYPE, NAME)                                                                        \
    __attribute__((always_inline)) inline void NAME(const corner_t corner, const int sy, const int sz,         \
                                                    const int j, const TYPE *wx, const TYPE *wy, const TYPE *wz, \
                                                    const TYPE *dx, const TYPE *dy, const TYPE *dz, TYPE *gx,   \
                                                    TYPE *gy, TYPE *gz)                                         \
    {                                                                                                     \
        _Pragma("unroll") for (int rz = 0; rz < j; rz++) {                                                \
            TYPE plane = 0, plane_dx = 0, plane_dy = 0;                                                   \
            _Pragma("unroll") for (int ry = 0; ry < j; ry++) {                                            \
                TYPE line = 0, line_dx = 0;                                                               \
                _Pragma("unroll") for (int rx = 0; rx < j; rx++) {                                        \
                    const TYPE a = (TYPE)(CORNER_COEF(corner, sy, sz, j, rz, ry, rx));                   \
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
GROUP_GRADIENT(realt, group_gradient_tail)

/* What a grid's part of a segment needs besides its samples: the cell's last coefficient, and per
 * axis the position u in the cell and the B-spline weights w at lanes 0..7 (real8) and 8.. (realt:
 * the lanes past NS are unused) */
typedef struct {
    __global const coef_t *corner;
    int sy, sz;
    real inv_step; /* lattice cells per grid-0 fine cell: the gradient's scale */
    real8 u[3], w[3][MAX_ORDER];
    realt ut[3], wt[3][MAX_ORDER];
#ifdef CLW_SCALAR_POOL
    real q[MAX_ORDER * MAX_ORDER * MAX_ORDER]; /* the cell's q, decoded once for the samples and the gradient */
    int4 cell; /* the (x, y, z) in the slot of the cell's last coefficient, and the slot's box's ny */
#endif
} Basis;

/* Grid g's part of the segment at the sample points xm + radius xi_k D, sample k in lane k, from the
 * brick in `slot` (-1: none, all weights 0).  Every sample comes from the lattice cell holding the
 * midpoint, so from the same polynomial. */
inline void segment_basis(const Field G, const int g, const int slot, const real3 xm, const real radius,
                          const real3 D, __constant const real *nodes, Basis *B)
{
    /* the lanes' points straight from nodes (lanes past NS repeat lane 0): vector loads of a private
     * array's scalar stores stalled on store forwarding */
    const real8 xi = vload8(0, nodes);
#if NS > 12
    const realt xit = vload8(1, nodes);
#else
    const realt xit = (real4)(nodes[8], nodes[NS > 9 ? 9 : 0], nodes[0], nodes[0]);
#endif
    const int j = ORDER[g];
    const real4 f = slot < 0 ? (real4)(0) : to_real4(G.frames[slot * CLW_GROUPS + g]);
    const int4 n = slot < 0 ? (int4)(j, j, j, 0) : G.boxes[slot * CLW_GROUPS + g];
    const real3 x = (xm - f.xyz) * f.w; /* the brick's lattice coordinates (docs/raytracing.md §3) */
    const int4 c = (int4)(clamp(convert_int4((real4)(floor(x), 0)).xyz, j - 1, n.xyz - 1), 0);
    const real3 u = x - convert_real3(c.xyz), step = radius * D * f.w; /* x - cell at xi = 0, and per unit xi */
    const real ua[3] = {u.x, u.y, u.z}, sa[3] = {step.x, step.y, step.z};
    for (int a = 0; a < 3; a++) {
        B->u[a] = ua[a] + sa[a] * xi;
        B->ut[a] = ua[a] + sa[a] * xit;
        bspline_weights8(j, B->u[a], B->w[a]);
        bspline_weights_tail(j, B->ut[a], B->wt[a]);
    }
    if (slot < 0)
        for (int a = 0; a < 3; a++)
            for (int r = 0; r < j; r++) {
                B->w[a][r] = 0;
                B->wt[a][r] = 0;
            }
    B->inv_step = f.w;
    B->sy = n.x;
    B->sz = n.x * n.y;
    B->corner = G.coef + n.w + ((size_t)c.z * n.y + c.y) * n.x + c.x;
#ifdef CLW_SCALAR_POOL
    B->cell = (int4)(c.xyz, n.y);
#endif
}

#ifdef CLW_SCALAR_POOL
/* The q of the segment's cell (the j^3 coefficients ending at B->cell, its lattice coordinates from segment_basis)
 * from the packed pool into B->q, in CORNER_COEF's order: one decode a segment, for its samples and its gradient
 * (slot -1: q = 0) */
__attribute__((always_inline)) inline void scalar_cell(const Field G, const int slot, const Quant Q, const int j,
                                                       Basis *B)
{
    if (slot < 0) {
        for (int i = 0; i < j * j * j; i++)
            B->q[i] = 0;
        return;
    }
    pool_cell(G.coef, Q, B->sy, B->cell.w, B->cell, j, B->q);
}

/* group_field for a scalar pool, from the decoded q: one lane a sample (samples 0..7 in *f, the tail lanes in *ft
 * when `tail`), where group_field's four channel lanes a sample would sum three of zeros */
__attribute__((always_inline)) inline void scalar_field(const Basis *B, const int j, const bool tail, real8 *f,
                                                        realt *ft)
{
#pragma unroll
    for (int rz = 0; rz < j; rz++) {
        real8 plane = 0;
        realt plane_t = 0;
#pragma unroll
        for (int ry = 0; ry < j; ry++) {
            real8 line = 0;
            realt line_t = 0;
#pragma unroll
            for (int rx = 0; rx < j; rx++) {
                const real c = CORNER_COEF(B->q, B->sy, B->sz, j, rz, ry, rx);
                line = fma((real8)(c), B->w[0][rx], line);
                if (tail)
                    line_t = fma((realt)(c), B->wt[0][rx], line_t);
            }
            plane = fma(line, B->w[1][ry], plane);
            if (tail)
                plane_t = fma(line_t, B->wt[1][ry], plane_t);
        }
        *f = fma(plane, B->w[2][rz], *f);
        if (tail)
            *ft = fma(plane_t, B->wt[2][rz], *ft);
    }
}

#define SCALAR_FIELD(J) \
    case J: \
        scalar_cell(G, A->slot, Q, J, B); \
        if (tail) \
            scalar_field(B, J, true, &f, &ft); \
        else \
            scalar_field(B, J, false, &f, &ft); \
        break;

/* sample_segment for a scalar pool (one group): fq[k] = (s_k, 0, 0, 0) */
inline void sample_segment(const Field G, Active *A, const real t_mid, const real3 xm, const real radius,
                           const real3 D, __constant const real *nodes, const bool fresh, real4 *fq,
                           Basis *basis)
{
    const bool tail = NS > 12 || NS > P0 + 1 || fresh; /* samples 8.. (lane P0 alone: only when fresh) */
    Basis *B = &basis[0];
    segment_basis(G, 0, A->slot, xm, radius, D, nodes, B);
    /* the slot's coefficients are offset + step q and the B-splines sum to 1 (their derivatives to 0): s is
     * offset + step times the sum over q, and the gradient step times its sum (no brick: weights 0, s = 0) */
    const Quant none = {0, 0, 0, 0}, Q = A->slot < 0 ? none : G.quant[A->slot];
    B->inv_step *= Q.step;
    real8 f = 0;
    realt ft = 0;
    switch (ORDER[0]) {
    SCALAR_FIELD(1)
    SCALAR_FIELD(2)
    SCALAR_FIELD(3)
    SCALAR_FIELD(4)
#if MAX_ORDER > 4
    SCALAR_FIELD(6)
#endif
    }
    f = fma(f, (real8)(Q.step), (real8)(Q.offset));
    ft = fma(ft, (realt)(Q.step), (realt)(Q.offset));
    real s[16];
    vstore8(f, 0, s);
#if NS > 12
    vstore8(ft, 1, s);
#else
    vstore4(ft, 2, s);
#endif
    for (int k = 0; k < NS; k++)
        fq[k] = (real4)(s[k], 0, 0, 0);
}
#else
/* group_field with a literal order and tail (the loops unroll): w, w8 and the sums as group_field's */
#define GROUP_FIELD(J) \
    case J: \
        if (tail) \
            group_field(B->corner, B->sy, B->sz, J, true, w, w8, f, &f8); \
        else \
            group_field(B->corner, B->sy, B->sz, J, false, w, w8, f, &f8); \
        if (NS > 12) /* samples 8..15 like 0..7 */ \
            group_field(B->corner, B->sy, B->sz, J, false, wt, w8, f + 2, &f8); \
        break;

/* The field at the segment's sample points (lane P0 only when `fresh` or when it shares a vector
 * with other tail lanes: else it is the last segment's end), and each grid's Basis for the gradient */
inline void sample_segment(const Field G, Active *A, const real t_mid, const real3 xm, const real radius,
                           const real3 D, __constant const real *nodes, const bool fresh, real4 *fq,
                           Basis *basis)
{
    real16 f[4] = {0, 0, 0, 0};
    real8 f8 = 0;
    const bool tail = NS < 12 && (NS > P0 + 1 || fresh); /* samples 8, 9 (NS = 16: the second call's) */
    const int slot = A->slot; /* every segment lies in the brick (or piece) the ray last entered */
    for (int g = 0; g < CLW_GROUPS; g++) {
        Basis *B = &basis[g];
        segment_basis(G, g, slot, xm, radius, D, nodes, B);
        const int j = ORDER[g];
        real16 w[3][MAX_ORDER][2], wt[3][MAX_ORDER][2];
        real8 w8[3][MAX_ORDER];
        for (int a = 0; a < 3; a++)
            for (int r = 0; r < j; r++) {
                w[a][r][0] = B->w[a][r].s0000111122223333;
                w[a][r][1] = B->w[a][r].s4444555566667777;
#if NS > 12
                wt[a][r][0] = B->wt[a][r].s0000111122223333;
                wt[a][r][1] = B->wt[a][r].s4444555566667777;
                w8[a][r] = 0;
#else
                w8[a][r] = B->wt[a][r].s00001111;
#endif
            }
        switch (j) {
        GROUP_FIELD(1)
        GROUP_FIELD(2)
        GROUP_FIELD(3)
        GROUP_FIELD(4)
#if MAX_ORDER > 4
        GROUP_FIELD(6)
#endif
        }
    }
    real *out = (real *)fq;
    vstore16(f[0], 0, out);
    vstore16(f[1], 1, out);
    if (NS > 12) {
        vstore16(f[2], 2, out);
        vstore16(f[3], 3, out);
    } else if (NS > P0 + 1) {
        vstore8(f8, 4, out);
    } else {
        vstore4(f8.lo, 8, out);
    }
}
#endif

#ifdef CLW_SHADE /* a gradient is for shading: an X-ray render of a model without alpha has CLW_ALPHA -1 */
/* alpha's fine gradient in the lanes of (gx, gy, gz), only for segments shaded point by point:
 * lanes 0..7 (real8), and the tail lanes 8.. (realt) unless lane P0 comes from the last segment and is the
 * only one there (NS < 16) */
#define GRADIENT_LANES(W, TYPE, DERIVATIVES, GRADIENT, U, OUT)                                             \
    {                                                                                                     \
        TYPE d[3][MAX_ORDER], hx = 0, hy = 0, hz = 0;                                                     \
        for (int a = 0; a < 3; a++)                                                                       \
            DERIVATIVES(j, B->U[a], d[a]);                                                                \
        const corner_t c = CORNER(B);                                                                     \
        const TYPE *wx = B->W[0], *wy = B->W[1], *wz = B->W[2];                                           \
        switch (j) { /* order 1 has no gradient: shading is off for Haar alpha */                         \
        case 2: GRADIENT(c, B->sy, B->sz, 2, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break;         \
        case 3: GRADIENT(c, B->sy, B->sz, 3, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break;         \
        case 4: GRADIENT(c, B->sy, B->sz, 4, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break;         \
        GRADIENT_6(GRADIENT)                                                                              \
        }                                                                                                 \
        gx->OUT = hx * B->inv_step; gy->OUT = hy * B->inv_step; gz->OUT = hz * B->inv_step;               \
    }
#if MAX_ORDER > 4
#define GRADIENT_6(GRADIENT) case 6: GRADIENT(c, B->sy, B->sz, 6, wx, wy, wz, d[0], d[1], d[2], &hx, &hy, &hz); break;
#define TAIL_LANES hi
#else
#define GRADIENT_6(GRADIENT)
#define TAIL_LANES s89ab
#endif
inline void sample_gradient(const Basis *basis, const bool all, realv *gx, realv *gy, realv *gz)
{
    const Basis *B = &basis[CLW_ALPHA];
    const int j = ORDER[CLW_ALPHA];
    *gx = 0; *gy = 0; *gz = 0;
    GRADIENT_LANES(w, real8, bspline_derivatives8, group_gradient8, u, lo)
    if (all || NS > 12)
        GRADIENT_LANES(wt, realt, bspline_derivatives_tail, group_gradient_tail, ut, TAIL_LANES)
}
#endif
#endif
