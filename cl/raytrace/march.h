/* march.h: how a ray walks the grid-0 fine lattice (cl/raytrace/raytrace.cl): the knot planes of a lattice ahead of
 * it, the empty-space blocks and superblocks and the bounds they carry for skipping and R (docs/raytracing.md §4),
 * and the content table's cells.  Needs types.h (real, real3, real4) and the shared constants CLW_BLOCK and
 * CLW_SUPER_CELLS. */
#ifndef CLW_MARCH_H
#define CLW_MARCH_H

/* Per axis, the next plane x_a = lat_a + k lat.w of a lattice of knot planes (origin lat.xyz, spacing
 * lat.w) that the ray x0 + t dd meets: its index k and its t */
typedef struct {
    real3 t;
    int3 k;
} Planes;

/* the next planes beyond t; inv = 1 / dd (products: divisions were a tenth of the march) */
inline Planes next_planes(const real *x0, const real *dd, const real *inv, const real t, const real4 lat)
{
    const real o[3] = {lat.x, lat.y, lat.z}, h = lat.w;
    real tp[3];
    int plane[3];
    for (int a = 0; a < 3; a++) {
        const real x = x0[a] + t * dd[a] - o[a];
        plane[a] = dd[a] > 0 ? (int)floor(x / h) + 1 : (int)ceil(x / h) - 1;
        tp[a] = dd[a] == 0 ? INFINITY : (plane[a] * h + o[a] - x0[a]) * inv[a];
        while (tp[a] <= t) { /* x sat on a plane but rounded to its near side */
            plane[a] += dd[a] > 0 ? 1 : -1;
            tp[a] = (plane[a] * h + o[a] - x0[a]) * inv[a];
        }
    }
    const Planes P = {(real3)(tp[0], tp[1], tp[2]), (int3)(plane[0], plane[1], plane[2])};
    return P;
}

/* past the planes met at tn: the next ones along those axes (step: +1 or -1 per axis, the sign of dd).
 * All three axes at once, in registers: per axis, the compiler stored two lanes of an array and read the
 * third back, which stalled the store forwarding on every segment (5 % of a render) */
inline void step_planes(const real3 x0, const real3 inv, const int3 step, const real tn, const real4 lat, Planes *P)
{
    const real3 moved = (convert_real3(P->k + step) * lat.w + lat.xyz - x0) * inv;
    P->k += step & convert_int3(P->t <= tn);
    P->t = select(P->t, moved, P->t <= tn);
}

/* the nearest of the three planes */
inline real nearest(const Planes *P) { return fmin(P->t.x, fmin(P->t.y, P->t.z)); }

/* where the segment from t ends: at the next knot plane of lattice lat, or at `end` (brick, piece or pass) if sooner;
 * the planes are found anew from t after a jump (*replan) */
inline real segment_end(const real *x0, const real *dd, const real *inv, const real t, const real4 lat, const real end,
                        Planes *planes, bool *replan)
{
    if (*replan) {
        *planes = next_planes(x0, dd, inv, t, lat);
        *replan = false;
    }
    return fmin(end, nearest(planes));
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

/* The bounds on |field| for skipping and R: per CLW_BLOCK^3 block, and per superblock of CLW_SUPER_CELLS^3
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
        const real sb = block_bound(R->super, R->super_origin, R->super_shape, xm, CLW_SUPER_CELLS, &b);
        const real sexit = fmax(block_exit(x0, dd, inv, b, CLW_SUPER_CELLS, t1), tn);
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

/* The bound integrated over [s, *tn], region by region, where the ray enters a new region at s: a segment of a
 * coarser lattice may cross several blocks, whose bounds all count (the midpoint's alone could skip, or end the ray
 * on, what the others hold).  The segment ends where it would enter a region of bound 0 (*tn moves there): a block no
 * content reaches is empty in the model (docs/raytracing.md §4, §8), whatever the coarse lattice's field holds there.
 * The block planes are stepped, not found anew per block; *bnd and *end are left at the region where the next
 * segment starts, so that it needs no second look-up. */
inline real swept_bound(const real *x0, const real *dd, const real *inv, const real3 X0, const real3 D,
                        const real3 inv3, const int3 step, real s, real *tn, const real t1, const Regions *R,
                        real *fine_end, real *bnd, real *end)
{
    const real4 blocks = (real4)(0, 0, 0, CLW_BLOCK);
    real sum = 0;
    Planes P = next_planes(x0, dd, inv, s, blocks);
    while (s < *tn) {
        const real sn = fmin(*tn, nearest(&P));
        *bnd = region_bound(x0, dd, inv, X0 + (s + sn) / 2 * D, sn, t1, R, fine_end, end);
        if (*bnd == 0) {
            *tn = s;
            break;
        }
        const real e = fmin(*end, *tn); /* past a coarse superblock at once */
        sum += *bnd * (e - s);
        s = e;
        if (e > sn)
            P = next_planes(x0, dd, inv, s, blocks);
        else
            step_planes(X0, inv3, step, sn, blocks, &P);
    }
    return sum;
}

/* whether the grid-0 fine cell holding x is reached by a non-zero voxel of the source volume
 * (clwave.raytrace.bounds.content_cells); cells outside the table are not */
inline bool reached(__global const uchar *content, const int4 origin, const int4 shape, const real3 x)
{
    const int4 k = convert_int4((real4)(floor(x), 0)) - origin;
    if (k.x < 0 || k.y < 0 || k.z < 0 || k.x >= shape.x || k.y >= shape.y || k.z >= shape.z)
        return false;
    return content[((size_t)k.z * shape.y + k.y) * shape.x + k.x] != 0;
}

#endif
