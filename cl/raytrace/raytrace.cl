/* raytrace.cl: the emission-absorption integral per pixel (paper §3, eq. 5 and 17).
 *
 * One work-item per ray.  The ray is cut at every knot plane of the channel groups' lattices;
 * inside a segment the field and the gradient of alpha are polynomials in t, sampled at
 * CLW_SAMPLES points (lanes 0..7: xi = -1 + p/4 for p = 1..8, lane 8: p = 0, lanes 9..: more points for
 * cubics and quintics, clwave/raytrace/quadrature.py).  Optical depth and X-ray integrals are exact from those samples, the emission integral
 * comes from adaptive Simpson with Phong-shaded q, and the tolerance is shared between quadrature,
 * early termination and empty-space skipping: docs/raytracing.md §2 (the error budget), §4
 * (blocks and superblocks), §5 (shading).  The field comes from the backend header
 * (field_bspline.h or field_wavelet.h), the segment integrals from quadrature.h, the walk along the lattice and
 * the empty-space bounds from march.h.
 *
 * Compile-time: CLW_GROUPS grids with orders CLW_ORDERS; CLW_ALPHA the grid holding alpha;
 * CLW_SAMPLES samples per segment (9, 10 or 16); CLW_JOIN when every order is >= 3; CLW_LATTICE 1 or
 * 0.5 (orders of both parities); CLW_SHADE for Phong shading; CLW_XRAY for line integrals;
 * CLW_DOUBLE for a float64 build; CLW_POST to classify a scalar by a transfer function while rendering. */
#include "raytrace/types.h"
#ifdef CLW_WAVELET
#include "raytrace/field_wavelet.h"
#else
#include "raytrace/field_bspline.h"
#endif
#include "raytrace/quadrature.h"
#include "raytrace/march.h"
#ifdef CLW_POST
#include "raytrace/classify.h"
#define POST 1
#else
#define POST 0
#endif

/* raytrace: one ray per pixel.
 *
 * Parameters
 *   image        out (H, W) float4: premultiplied (R, G, B, 1 - T), or line integrals (CLW_XRAY)
 *   stats        out (H, W) int4: segments, segments shaded at the midpoint (no gradient), integrand
 *                    evaluations, flags
 *                    (bit 0 terminated early, bit 1 Simpson depth limit reached, bit 2 active list overflowed)
 *   lattice_stats out (H, W) int4: the segments on knot lattices of 1 (or 1/2), 2, 4, and 8 or more cells
 *   FIELD_PARAMS the field backend's arguments: the brick pool, page table and per-slot tables
 *                (field_bspline.h), or the wavelet bands and their tables (field_wavelet.h)
 *   bound, occ_origin, occ_shape bound on |field| per CLW_BLOCK^3 block (grid-0 fine coordinates / block)
 *   super_bound, super_origin, super_shape  the largest of those per superblock of CLW_SUPER_CELLS^3 fine cells
 *   content, content_origin, content_shape  CLW_CONTENT builds: per grid-0 fine cell, 1 where the source
 *                volume's content reaches; the segments of other cells are empty (docs/raytracing.md §4)
 *   coarse_bound superblocks bounded by at most this are one region for skipping and R
 *   box_lo, box_hi               clip box of the model's support, grid-0 fine coordinates (and of a clip's box)
 *   clip, nclip                  the clip's half-spaces in the kernel's world, (n, d) keeping n . x + d >= 0
 *                                (docs/raytracing.md §12)
 *   base, du, dv, dir            rays in the kernel's world: world units about the volume's centre (world - origin,
 *                                docs/coordinates.md §1); orthographic p = base + c du + r dv, w = dir;
 *                                perspective p = base (the eye), w = normalize(dir + c du + r dv) (a cone beam's
 *                                principal point in dir), with c, r the pixel centre's offsets from the image centre
 *   to_fine_scale, to_fine_offset  grid-0 fine coordinates = world * scale + offset
 *   nodes        the sample points xi_k (CLW_SAMPLES), then the (CLW_SAMPLES, CLW_SAMPLES) matrix
 *                from the samples to the field's Chebyshev series, then the (NG, NG) one from lanes
 *                0..NG-1 to the gradient's (types.h)
 *   weights      (CLW_SAMPLES, 8) sample k's weights in the integral from -1 to xi = -1 + p/4,
 *                p = 1..8, of the polynomial through the samples (p = 8: the whole segment)
 *   tol          absolute tolerance per output value
 *   shade_gain   how much shading can scale the emission (the shaded q <= shade_gain |field|)
 *   grad_floor   shorter world gradients of alpha get no diffuse or specular light: on a plateau
 *                of alpha they are rounding noise, whose random normals would make the integrand
 *                jump everywhere
 *   lights       (nlights,) unit directions towards the lights; phong (ka, kd, ks, shininess)
 *   tf           CLW_POST builds: the transfer function's table (classify.h) that classifies the scalar
 *                (channel 0); the bounds then bound the classified opacity
 *   passes       0: one pass over the whole ray.  Else the ray is marched only inside the box pass_lo ..
 *                pass_hi (grid-0 fine coordinates), going on from carry (premultiplied colour and T, or the
 *                X-ray integrals), ledger (the skipping and shading budgets left, R consumed, and R of the
 *                whole ray: 0 before the first pass), resume (where the last pass stopped, -inf before the first: a
 *                coarse segment may end past a pass's box) and stats, which it updates (docs/raytracing.md §6)
 * Grid: global (W, rows), rows first_row .. of a band (clwave.device.kernels.in_row_bands). */
__kernel void raytrace(__global float4 *image, __global int4 *stats, __global int4 *lattice_stats, const int width,
                       const int height, const int first_row, FIELD_PARAMS,
                       __global const float *bound, const int4 occ_origin, const int4 occ_shape,
                       __global const float *super_bound, const int4 super_origin, const int4 super_shape,
                       __global const uchar *content, const int4 content_origin, const int4 content_shape,
                       const real coarse_bound, const float4 box_lo, const float4 box_hi,
                       __constant const float4 *clip, const int nclip,
                       const float4 base, const float4 du, const float4 dv, const float4 dir, const int perspective,
                       const float4 to_fine_scale, const float4 to_fine_offset,
                       __constant const real *nodes, __constant const real *weights, const real tol,
                       const real shade_gain, const real grad_floor,
                       __constant const float4 *lights, const int nlights, const float4 phong, __global const real4 *tf,
                       const int passes, const float4 pass_lo, const float4 pass_hi, __global real4 *carry,
                       __global real4 *ledger, __global real *resume)
{
    const int col = get_global_id(0), row = first_row + get_global_id(1);
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
    const real3 inv3 = (real3)(inv[0], inv[1], inv[2]);
    const int3 step = (int3)(D.x > 0 ? 1 : -1, D.y > 0 ? 1 : -1, D.z > 0 ? 1 : -1);
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
    for (int k = 0; k < nclip; k++) { /* the clip's half-spaces: the interval stays one (docs/raytracing.md §12) */
        const real at = dot(to_real3(clip[k].xyz), p) + clip[k].w, rate = dot(to_real3(clip[k].xyz), w);
        if (rate > 0)
            t0 = fmax(t0, -at / rate);
        else if (rate < 0)
            t1 = fmin(t1, -at / rate);
        else if (at < 0)
            t1 = -INFINITY;
    }
    const Regions regions = {bound, super_bound, occ_origin, occ_shape, super_origin, super_shape, coarse_bound};
    const size_t pix = (size_t)row * width + col;
    Active active;
    active_init(&active, G, pix, X0, D);
    int segments = 0, midpoints = 0, evals = 0, flags = 0;
    int4 spans = (int4)(0); /* segments on lattices of 1 (or 1/2), 2, 4, and 8 or more cells */
    if (passes) { /* docs/raytracing.md §6: go on from the last pass; a terminated ray is done */
        const int4 s = stats[pix];
        segments = s.x; midpoints = s.y; evals = s.z; flags = s.w;
        spans = lattice_stats[pix];
    }
    if (!(t1 > t0) || (flags & 1)) {
        if (!passes) {
            image[pix] = (float4)(0.0f);
            stats[pix] = (int4)(0);
            lattice_stats[pix] = (int4)(0);
        }
        return;
    }
    real ta = t0, tb = t1; /* the part of the ray this pass marches: inside the pass box */
    if (passes) {
        const real plo[3] = {pass_lo.x, pass_lo.y, pass_lo.z}, phi[3] = {pass_hi.x, pass_hi.y, pass_hi.z};
        for (int a = 0; a < 3; a++) {
            if (dd[a] == 0) {
                if (x0[a] < plo[a] || x0[a] >= phi[a])
                    tb = -INFINITY;
            } else {
                const real ea = (plo[a] - x0[a]) * inv[a], eb = (phi[a] - x0[a]) * inv[a];
                ta = fmax(ta, fmin(ea, eb));
                tb = fmin(tb, fmax(ea, eb));
            }
        }
        ta = fmax(ta, resume[pix]); /* the last pass's last segment (or skip) may have ended past its box */
        if (!(tb > ta))
            return;
    }

#ifndef CLW_XRAY
    Shading P;
    P.ka = phong.x; P.kd = phong.y; P.ks = phong.z; P.shininess = phong.w;
    P.whole = phong.w == floor(phong.w) && phong.w <= 64; /* powers by squaring (quadrature.h) */
    P.exponent = (int)phong.w;
    /* world gradients in units of the floor, a power of two (the same normals, bit for bit): their squares stay
     * normal numbers at any data scale (a scalar of 1e-20 squared them to 0, flat everywhere) */
    const real unit = grad_floor > 0 ? ldexp((real)(1), -ilogb((real)(grad_floor))) : (real)(1);
    P.grad_floor = grad_floor * unit;
    P.nlights = min(nlights, CLW_MAX_LIGHTS);
    P.scale = scale * unit;
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
    /* R(t0): the region bounds integrated along the whole ray, region by region (once, in the first pass) */
    real rest = 0, consumed = 0;
    if (passes) {
        const real4 c = carry[pix], l = ledger[pix];
        I = c.xyz; T = c.w;
        skip_budget = l.x; shade_budget = l.y; consumed = l.z; rest = l.w;
    }
    if (!(rest > 0)) {
        real fine_end = -INFINITY;
        const real4 blocks = (real4)(0, 0, 0, CLW_BLOCK);
        Planes bp = next_planes(x0, dd, inv, t0, blocks);
        for (real t = t0; t < t1;) {
            const real tn = fmin(t1, nearest(&bp));
            real end;
            rest += region_bound(x0, dd, inv, X0 + (t + tn) / 2 * D, tn, t1, &regions, &fine_end, &end) * (end - t);
            if (end > tn) { /* a coarse superblock: on past it */
                t = end;
                bp = next_planes(x0, dd, inv, t, blocks);
            } else {
                t = tn;
                step_planes(X0, inv3, step, tn, blocks, &bp);
            }
        }
    }
    /* R(t) = rest - consumed, the part of the sum at t' < t subtracted as the march passes it;
     * slack covers the rounding of the two sums (float32: ~1e-7 relative per term) */
    const real slack = rest * (real)1e-4;
#else
    real4 I = (real4)(0);
    real skip_budget = tol / 2;
    if (passes) {
        I = carry[pix];
        skip_budget = ledger[pix].x;
    }
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
    /* the knot planes of the brick the ray is in (the field's lattice there), and where it leaves the brick */
    real4 lat = (real4)(0, 0, 0, CLW_LATTICE);
    real brick_end = FIELD_BRICK ? -INFINITY : INFINITY;
    real cut_end = tb; /* where segments are cut: the brick's face, or the next brick's where that one goes on */
    real piece_end = INFINITY; /* in a mixed brick, where the ray leaves the piece it is in */
    Planes planes;
    real t = ta;
    bool replan = true;
    while (t < tb) {
        if (!(t < brick_end)) { /* a new brick: its lattice, and where the ray leaves it */
            const Planes faces = next_planes(x0, dd, inv, t, (real4)(0, 0, 0, FIELD_BRICK));
            const real face = nearest(&faces);
            brick_end = fmin(tb, face);
            lat = field_lattice(G, X0 + (t + brick_end) / 2 * D, &active);
            replan = true;
            cut_end = brick_end;
#ifdef FIELD_MIXES
            piece_end = field_mixed(&active) ? -INFINITY : INFINITY;
            /* a coarse lattice that the next brick goes on with: segments cross the face (the next one starts the
             * look-up of that brick), so a lattice cell cut by a face is one segment, not two; also where a pass's
             * box ends there (the next pass starts where the segment ended), so that passes cut as one pass does */
            if (lat.w > CLW_LATTICE && face < t1 && !field_mixed(&active)) {
                Planes next = faces;
                step_planes(X0, inv3, step, face, (real4)(0, 0, 0, FIELD_BRICK), &next);
                const real beyond = fmin(t1, nearest(&next));
                if (field_continues(G, X0 + (face + beyond) / 2 * D, lat))
                    cut_end = beyond;
            }
        }
        if (!(t < piece_end)) { /* a mixed brick's next run of pieces with one flag: the coarse slot or the fine one */
            Planes cuts = next_planes(x0, dd, inv, t, active.piece_lat);
            piece_end = fmin(brick_end, nearest(&cuts));
            /* a piece's index is that of the cut planes ahead of it (stepped by step_planes as the ray crosses
             * them) less a constant of the run: no floors or divisions per piece */
            const int3 from_cuts = piece_index(X0 + (t + piece_end) / 2 * D, &active) - cuts.k;
            const int flag = field_piece(G, cuts.k + from_cuts, &active);
            while (piece_end < brick_end) {
                step_planes(X0, inv3, step, piece_end, active.piece_lat, &cuts);
                const real next = fmin(brick_end, nearest(&cuts));
                if (field_piece(G, cuts.k + from_cuts, &active) != flag)
                    break;
                piece_end = next;
            }
            lat = field_run(&active, flag);
            replan = true;
            if (flag == PIECE_EMPTY && !POST) { /* no content reaches: the field is 0 (as CLW_CONTENT's cells below);
                                                * post-classified, 0 is classified (marched on the fine slot) */
                t = piece_end;
                continue;
            }
#endif
        }
        /* a segment of a coarser lattice may cross blocks: the region holding t decides a skip, before the segment's
         * end is planned (a skip needs none), and what a marched segment passes is summed below */
        const bool coarse = lat.w > CLW_LATTICE;
        if (coarse && !(t < texit)) {
            const Planes faces = next_planes(x0, dd, inv, t, (real4)(0, 0, 0, CLW_BLOCK));
            const real tface = nearest(&faces);
            bnd = region_bound(x0, dd, inv, X0 + (t + tface) / 2 * D, tface, t1, &regions, &fine_end, &texit);
        }
        real tn = coarse ? t : segment_end(x0, dd, inv, t, lat, fmin(fmin(cut_end, piece_end), t1), &planes, &replan);
        if (!coarse && !(tn <= texit)) /* a new block or superblock: its bound, and where the ray leaves it */
            bnd = region_bound(x0, dd, inv, X0 + (t + tn) / 2 * D, tn, t1, &regions, &fine_end, &texit);
        const real swept = bnd * (texit - t); /* the bound integrated over [t, texit]: what a skip passes */
#ifdef CLW_XRAY
        const real cost = swept;
#else
        const real rest_after = fmax(rest - consumed - swept, (real)0) + slack;
        const real cost = T * swept * (shade_gain * (1 + rest_after) + 1);
#endif
        if (cost <= skip_budget) { /* (nearly) empty region: jump to where the ray leaves it */
            skip_budget -= cost;
#ifndef CLW_XRAY
            consumed += swept;
#endif
            t = texit;
            replan = true;
            continue;
        }
        real marched = bnd * (tn - t); /* the bound integrated over the segment */
        if (coarse) {
            tn = segment_end(x0, dd, inv, t, lat, fmin(fmin(cut_end, piece_end), t1), &planes, &replan);
            marched = bnd * (fmin(tn, texit) - t);
            if (tn > texit) /* it crosses blocks: each one's bound counts, and it ends before an empty one */
                marched += swept_bound(x0, dd, inv, X0, D, inv3, step, texit, &tn, t1, &regions, &fine_end, &bnd,
                                       &texit);
        }
        const real3 xm = X0 + (t + tn) / 2 * D;
#ifdef CLW_CONTENT
        if (tn > t && !reached(content, content_origin, content_shape, xm)) { /* no content reaches: empty */
            t = tn;
            step_planes(X0, inv3, step, tn, lat, &planes);
            continue;
        }
#endif
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
            {
                const int lv = lat.w <= 1 ? 0 : lat.w <= 2 ? 1 : lat.w <= 4 ? 2 : 3;
                spans += (int4)(lv == 0, lv == 1, lv == 2, lv == 3);
            }
#ifdef CLW_XRAY /* the integral over the segment */
            real4 integral = (real4)(0);
            for (int k = 0; k < NS; k++)
                integral += S.fq[k] * weights[8 * k + 7];
            I += S.radius * integral;
#else
            real3 part;
            real depth; /* int alpha dxi over the segment */
#ifdef CLW_POST
            {   /* the scalar classified by the transfer function (classify.h, docs/raytracing.md §10) */
                real s[NS], u[NS], c[NS];
                for (int k = 0; k < NS; k++)
                    s[k] = S.fq[k].x;
                OneInterval O;
                bool one;
                real4 r; /* (int q' e^{-A} dxi, int alpha dxi) */
                const bool gradient_joined = joined && end_shaded; /* lane P0's gradient: the last segment's end */
                end_shaded = false;
                if (!post_segment(s, nodes, weights, tf, &P, S.radius, T * S.radius, &shade_budget, u, c, &O, &one,
                                  &r, &midpoints, &evals)) {
#ifdef CLW_SHADE
                    sample_gradient(basis, !gradient_joined, &S.gx, &S.gy, &S.gz);
                    if (gradient_joined) {
                        S.gx.s8 = end_gradient.x; S.gy.s8 = end_gradient.y; S.gz.s8 = end_gradient.z;
                    }
                    end_gradient = (real3)(S.gx.s7, S.gy.s7, S.gz.s7);
                    end_shaded = true;
#else
                    S.gx = 0; S.gy = 0; S.gz = 0;
#endif
                    r = post_gradient(&O, one, c, u, S.gx, S.gy, S.gz, S.radius, nodes, weights, tf, &P,
                                      quadrature_share * (tn - t) / total / T / S.radius, &evals, &flags);
                }
                part = r.xyz;
                depth = r.w;
            }
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
            depth = A8.s7;
            const real8 att = fast_exp(-S.radius * A8);
            bool simpson_full = true; /* adaptive Simpson on the shaded integrand */
#ifdef CLW_SHADE
            if (midpoint_shading(r8 * att, g8 * att, b8 * att, a8 * att, f0, &P, T * S.radius, &shade_budget,
                                 &part)) { /* no gradient needed (docs/raytracing.md §5) */
                simpson_full = false;
                midpoints += 1;
                evals += 9;
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
#endif
            I += T * S.radius * part;
            T *= exp(-S.radius * depth);
            consumed += marched;
            const real left = fmax(rest - consumed, (real)0) + slack;
            if (T * fmax(fmin((real)1, left), shade_gain * left) <= tol / 4) {
                flags |= 1;
                break;
            }
#endif
        }
        t = tn;
        step_planes(X0, inv3, step, tn, lat, &planes);
    }
#ifdef CLW_XRAY
    image[pix] = convert_float4(I);
    if (passes) {
        carry[pix] = I;
        ledger[pix] = (real4)(skip_budget, 0, 0, 0);
        resume[pix] = t;
    }
#else
    image[pix] = (float4)(convert_float3(I), (float)(1 - T));
    if (passes) {
        carry[pix] = (real4)(I, T);
        ledger[pix] = (real4)(skip_budget, shade_budget, consumed, rest);
        resume[pix] = t;
    }
#endif
    stats[pix] = (int4)(segments, midpoints, evals, flags | active_flags(&active));
    lattice_stats[pix] = spans;
}
