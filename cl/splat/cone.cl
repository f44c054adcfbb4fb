/* cl/splat/cone.cl: perspective (cone-beam) splatting, docs/splatting.md §8.
 *
 * Built with -DCLW_PERSPECTIVE beside bin.cl (whose binning it shares; records carry the splat's depth,
 * cl/splat/record.h).  The ray of a pixel leaves the eye E along -n + s_u u + s_v v (slopes s); at the
 * depth z_c of a splat's centre X it passes X + w, w = z_c (s - s_c) in the plane through X parallel
 * to the detector.  Its integral over the basis function is G_s(w) = ∫ B(X + w + t (n - s_u u - s_v v)) dt
 * times the path length per unit depth sqrt(1 + |s|^2) (applied to the image on the host): exact.  The
 * footprint G_s depends on the slope, so every texture holds G at a grid of slopes (nodes) and each
 * pixel interpolates bilinearly between the four nodes around its own slope.
 *
 * Tables (clwave.splat.perspective.ConeTables):
 *   band_world  (64,) float4: world centre (x, y, z) of coefficient k = 0 of each band
 *   band_step   (64,) float4: world step per unit k_x, k_y, k_z (2^m d_x, 2^m d_y, 2^m d_z)
 *   band_tex    (64,) int: texture of each band, -1 when it is not drawn
 *   tex_box     (T,) float4: texture box in world units about the centre (a_min, a_max, b_min, b_max)
 *   tex_int     (T,) int4: (offset of cell 0's first texel, row stride in texels, slope refinement r, rows).
 *               The texture's nodes are the slope grid's with r steps to each of its steps ((k_u - 1) r + 1 by
 *               (k_v - 1) r + 1; docs/splatting.md §8 "Refined bands").  A cell of its nodes (its first node
 *               (i_u, i_v); cells row-major by v) is (rows, row stride) texels of 4 floats, its four nodes' samples
 *               (i_u, i_v), (i_u + 1, i_v), (i_u, i_v + 1), (i_u + 1, i_v + 1): a pixel's 16 reads are 2 runs of 8
 *               floats.  Every node has a zero margin of one texel all round
 *   tex_map     (T,) float4: (centre_u, centre_v) in texels of the unpadded texture, 1/h_u, 1/h_v
 *   tex_layer, layers: as bin.cl
 *   layer_slope (L,) float4: slope per pixel (sigma_u, sigma_v) of each layer
 *   cone        (6,) float4: eye, n, u, v; (s0_u, s0_v, lo_u, lo_v): the image centre's slopes and the
 *               first node's; (1 / step_u, 1 / step_v, nodes_u, nodes_v) of the slope grid, row-major by v */
#include "splat/record.h"

#ifndef CLW_PERSPECTIVE
#error "cone.cl is built with CLW_PERSPECTIVE"
#endif

/* The index of the layer holding a tile, and the tile's corner pixel in it */
inline int cone_layer(const int tile, const int layer_count, __global const int4 *layers, int2 *corner)
{
    int l = 0;
    while (l + 1 < layer_count && layers[l + 1].z <= tile)
        ++l;
    const int tiles_x = (layers[l].x + CLW_TILE - 1) / CLW_TILE, index = tile - layers[l].z;
    *corner = (int2)(index % tiles_x, index / tiles_x) * CLW_TILE;
    return l;
}

/* splat_project_cone: as bin.cl's splat_project, through the eye.
 *   centre  out (n,) float4: pixel (col, row) of the support centre in its layer, its depth, 0
 *   (the others as splat_project)
 * A splat whose centre is not in front of the eye is culled (the host refuses such views).
 * Grid: global (n,), any local size. */
__kernel void splat_project_cone(const uint n, const uint first, __global const int4 *coef,
                                 __global const int *band_tex, __global const float4 *band_world,
                                 __global const float4 *band_step, __global const float4 *tex_box,
                                 __global const int2 *tex_layer, __global const int4 *layers,
                                 __global const float4 *layer_slope, __global const float4 *cone,
                                 __global float4 *centre, __global int4 *bbox, __global int *stex,
                                 __global uint *count)
{
    const uint i = get_global_id(0);
    if (i >= n)
        return;
    const int4 c = coef[first + i];
    const int tex = band_tex[c.w];
    const float4 step = band_step[c.w];
    const float4 x = band_world[c.w] + (float4)((float)c.x * step.x, (float)c.y * step.y, (float)c.z * step.z, 0.0f);
    const float4 d = x - cone[0];
    const float depth = -dot(d, cone[1]);
    int4 box = (int4)(0, 0, -1, -1);
    uint cnt = 0;
    float col = 0.0f, row = 0.0f;
    if (tex >= 0 && depth > 0.0f) {
        const float4 b = tex_box[tex];
        const int l = tex_layer[tex].x;
        const int4 layer = layers[l];
        const float2 sigma = layer_slope[l].xy, s0 = cone[4].xy;
        col = (dot(d, cone[2]) / depth - s0.x) / sigma.x + 0.5f * (float)layer.x - 0.5f;
        row = 0.5f * (float)layer.y - 0.5f - (dot(d, cone[3]) / depth - s0.y) / sigma.y;
        /* the texture box in pixels: world offsets w at the splat's depth, w = depth * sigma * pixels */
        const float pu = 1.0f / (depth * sigma.x), pv = 1.0f / (depth * sigma.y);
        const float x0 = fmax(ceil(col + b.x * pu), 0.0f), x1 = fmin(floor(col + b.y * pu), (float)(layer.x - 1));
        const float y0 = fmax(ceil(row - b.w * pv), 0.0f), y1 = fmin(floor(row - b.z * pv), (float)(layer.y - 1));
        if (x0 <= x1 && y0 <= y1) {
            box = (int4)((int)x0, (int)y0, (int)x1, (int)y1);
            cnt = (uint)((box.z / CLW_TILE - box.x / CLW_TILE + 1) * (box.w / CLW_TILE - box.y / CLW_TILE + 1));
        }
    }
    centre[i] = (float4)(col, row, depth, 0.0f);
    bbox[i] = box;
    stex[i] = tex;
    count[i] = cnt;
}

/* Slope s's position along one axis of the slope grid, in steps from its first node (slopes beyond the grid take
 * its edge).  lo, inv: the first node's slope and 1 / step; nodes: the grid's along that axis. */
inline float cone_grid(const float s, const float lo, const float inv, const int nodes)
{
    return clamp((s - lo) * inv, 0.0f, (float)(nodes - 1));
}

/* The cell of a texture refined r times (tex_int.z) at grid position g along one axis: its first node (returned)
 * and the weight of the next. */
inline int cone_cell(const float g, const int r, const int nodes, float *w)
{
    const float gr = g * (float)r;
    const int i = min((int)gr, (nodes - 1) * r - 1);
    *w = gr - (float)i;
    return i;
}

/* The floats of one cell of a texture (tex_int ti): (rows, row stride) texels of 4 floats */
inline int cone_cell_floats(const int4 ti)
{
    return 4 * ti.y * ti.w;
}

/* A splat's sample at texel (tu, tv) of its texture's cell ci (its four nodes interleaved, see the tables above) with
 * slope weights (wu, wv); ti: the texture's tex_int.  Clamped onto the zero margin (index -1 .. size - 1 of the
 * unpadded texture, +1 for the margin).  Two reads of 8 floats: texels iu and iu + 1 of rows iv and iv + 1. */
inline float cone_sample(__global const float *texels, const int4 ti, const int ci, const float tu, const float tv,
                         const float wu, const float wv)
{
    const float fiu = floor(tu), fiv = floor(tv);
    const int iu = clamp((int)fiu, -1, ti.y - 3), iv = clamp((int)fiv, -1, ti.w - 3);
    const float fu = tu - fiu, fv = tv - fiv;
    __global const float *t = texels + ti.x + ci * cone_cell_floats(ti) + 4 * ((iv + 1) * ti.y + iu + 1);
    const float8 top = vload8(0, t), bottom = vload8(0, t + 4 * ti.y);
    const float4 w = (float4)((1.0f - wu) * (1.0f - wv), wu * (1.0f - wv), (1.0f - wu) * wv, wu * wv);
    const float s00 = dot(top.lo, w), s01 = dot(top.hi, w), s10 = dot(bottom.lo, w), s11 = dot(bottom.hi, w);
    return (1.0f - fv) * ((1.0f - fu) * s00 + fu * s01) + fv * ((1.0f - fu) * s10 + fu * s11);
}

/* 16 lanes' samples of one splat row: lane j's texels start at texels + at[j] (texel iu of row iv, its cell's four
 * nodes interleaved; row iv + 1 is `below` floats further).  Each lane blends its 2 x 2 texels' 8 floats in v (texel
 * weight fv) and then its nodes in v (the row's slope weights v0, v1) as one float8 and one float4 of its own,
 * leaving (node u, node u + 1) at texels iu, iu + 1; the lanes' four values are then gathered into vectors for the
 * blends in u (fu per lane for the texels, wu per lane for the nodes).  Blending before gathering: 4 values a lane
 * go into vectors rather than 16 (1.8-1.9x faster on the chest CT at 256^2, docs/benchmarks.md §11). */
inline float16 cone_row(__global const float *texels, const int *at, const int below, const float fv, const float v0,
                        const float v1, const float16 fu, const float16 wu)
{
    float4 q[16];
    for (int j = 0; j < 16; ++j) {
        const float8 t = (1.0f - fv) * vload8(0, texels + at[j]) + fv * vload8(0, texels + at[j] + below);
        q[j] = v0 * t.s0145 + v1 * t.s2367;
    }
#define CLW_L(c) (float16)(q[0].c, q[1].c, q[2].c, q[3].c, q[4].c, q[5].c, q[6].c, q[7].c, q[8].c, q[9].c, q[10].c, \
    q[11].c, q[12].c, q[13].c, q[14].c, q[15].c)
    return (1.0f - wu) * ((1.0f - fu) * CLW_L(x) + fu * CLW_L(z)) + wu * ((1.0f - fu) * CLW_L(y) + fu * CLW_L(w));
#undef CLW_L
}

/* splat_accumulate_cone: add every tile's records to the framebuffers.
 *   ranges, records, layers, fb: as cl/splat/raster.h (records sorted by tile, texture, importance)
 *   tex_int, tex_map, texels, layer_slope, cone: the tables above (texels with 16 zeros before)
 * A pixel's slope sets its position in the slope grid, and per splat its cell of the splat's texture's nodes (4
 * nodes, bilinear weights; a refined texture has r nodes to the grid's step); per splat its texel
 * position is w / h = depth * sigma * (pixel - centre) / h, and it reads 2 x 2 texels of each node (the
 * cell's 4 nodes are interleaved per texel).
 * Grid, -DCLW_CONE_TILE (CPUs): a work-item per tile, a row of 16 pixels a float16 (each lane's texels
 * gathered); otherwise (GPUs): a work-group of CLW_TILE^2 items per tile, a pixel each.  Either numbered from
 * first_tile, a band's first.
 * Assumes: every pixel owned by one work-item, splats in sorted order: bit-identical repeats. */
__kernel void splat_accumulate_cone(const int first_tile, const int layer_count, __global const int4 *layers,
                                    __global const float4 *layer_slope, __global const float4 *cone,
                                    __global const uint2 *ranges, __global const uint4 *records,
                                    __global const int4 *tex_int, __global const float4 *tex_map,
                                    __global const float *texels, __global float4 *fb)
{
#ifdef CLW_CONE_TILE
    const int tile = first_tile + get_global_id(0);
#else
    const int tile = first_tile + get_global_id(0) / (CLW_TILE * CLW_TILE);
    const int lid = get_local_id(0), lx = lid % CLW_TILE, ly = lid / CLW_TILE;
#endif
    int2 corner;
    const int l = cone_layer(tile, layer_count, layers, &corner);
    const int4 layer = layers[l];
    const float2 sigma = layer_slope[l].xy;
    const float4 grid = cone[4], cells = cone[5];
    const int ku = (int)cells.z, kv = (int)cells.w;
    const uint2 r = ranges[tile];
#ifdef CLW_CONE_TILE
    /* a row of the tile is 16 lanes: each lane's position in the slope grid along u once per tile, each row's
     * along v; per splat, each lane's cell of its texture's nodes and weight (cone_cell), and per row, each lane
     * reads its cell's four nodes at its 2 x 2 texels, 8 floats a read (cone_row); the arithmetic is in vectors */
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const float16 gu = clamp((grid.x + ((float)corner.x + 0.5f - 0.5f * (float)layer.x + lane) * sigma.x - grid.z)
                             * cells.x, 0.0f, (float)(ku - 1));
    float grow[CLW_TILE];
    float16 acc[CLW_CHANNELS][CLW_TILE];
    for (int i = 0; i < CLW_TILE; ++i) {
        grow[i] = cone_grid(grid.y + (0.5f * (float)layer.y - (float)(corner.y + i) - 0.5f) * sigma.y, grid.w,
                            cells.y, kv);
        for (int ch = 0; ch < CLW_CHANNELS; ++ch)
            acc[ch][i] = 0.0f;
    }
    for (uint k = r.x; k < r.y; ++k) {
        int4 bx;
        float4 cen, w;
        const int tex = splat_unpack(records + k * CLW_RECORD, &cen, &bx, &w);
        const float c[4] = {w.x, w.y, w.z, w.w};
        const int4 ti = tex_int[tex];
        const float4 tm = tex_map[tex];
        const int cell = cone_cell_floats(ti), cells_u = (ku - 1) * ti.z;  /* the texture's cells along u */
        const float16 gr = gu * (float)ti.z;
        const int16 ccol = min(convert_int16(gr), (int16)(cells_u - 1));
        const float16 wu = gr - convert_float16(ccol);
        const float ru = cen.z * sigma.x * tm.z, rv = cen.z * sigma.y * tm.w;  /* texels per pixel */
        const float16 tu = tm.x + ((float)corner.x - cen.x + lane) * ru;
        const float16 fiu = floor(tu), fu = tu - fiu;
        const int16 iu = clamp(convert_int16(fiu), (int16)(-1), (int16)(ti.y - 3));
        const int16 col = ti.x + 4 * (iu + 1) + ccol * cell;
        const float16 mask = select((float16)(0.0f), (float16)(1.0f),
                                    isgreaterequal(lane, (float16)(bx.x)) & islessequal(lane, (float16)(bx.z)));
        for (int y = bx.y; y <= bx.w; ++y) {
            const float tv = tm.y + (cen.y - (float)(corner.y + y)) * rv;
            const float fiv = floor(tv), fv = tv - fiv;
            float wv;
            const int crow = cone_cell(grow[y], ti.z, kv, &wv) * cells_u;
            const int16 at = col + (crow * cell + 4 * (clamp((int)fiv, -1, ti.w - 3) + 1) * ti.y);
            int ats[16];
            vstore16(at, 0, ats);
            const float16 sample = mask * cone_row(texels, ats, 4 * ti.y, fv, 1.0f - wv, wv, fu, wu);
            for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                acc[ch][y] += c[ch] * sample;
        }
    }
    for (int i = 0; i < CLW_TILE && corner.y + i < layer.y; ++i) {
        float out[4][16] = {{0}};
        for (int ch = 0; ch < CLW_CHANNELS; ++ch)
            vstore16(acc[ch][i], 0, out[ch]);
        for (int p = 0; p < 16 && corner.x + p < layer.x; ++p)
            fb[layer.w + (corner.y + i) * layer.x + corner.x + p] += (float4)(out[0][p], out[1][p], out[2][p], out[3][p]);
    }
#else
    const int x = corner.x + lx, y = corner.y + ly;
    const float gu = cone_grid(grid.x + ((float)x + 0.5f - 0.5f * (float)layer.x) * sigma.x, grid.z, cells.x, ku);
    const float gv = cone_grid(grid.y + (0.5f * (float)layer.y - (float)y - 0.5f) * sigma.y, grid.w, cells.y, kv);
    float4 acc = (float4)(0.0f);
    for (uint k = r.x; k < r.y; ++k) {
        int4 bx;
        float4 cen, c;
        const int tex = splat_unpack(records + k * CLW_RECORD, &cen, &bx, &c);
        if (lx < bx.x || lx > bx.z || ly < bx.y || ly > bx.w)
            continue;
        const float4 tm = tex_map[tex];
        const int4 ti = tex_int[tex];
        float wu, wv;
        const int nu = cone_cell(gu, ti.z, ku, &wu), nv = cone_cell(gv, ti.z, kv, &wv);
        const float tu = tm.x + ((float)x - cen.x) * cen.z * sigma.x * tm.z;
        const float tv = tm.y + (cen.y - (float)y) * cen.z * sigma.y * tm.w;
        acc += c * cone_sample(texels, ti, nv * (ku - 1) * ti.z + nu, tu, tv, wu, wv);
    }
    /* records hold every channel: the framebuffer's others keep their values */
    acc *= (float4)(1.0f, CLW_CHANNELS > 1 ? 1.0f : 0.0f, CLW_CHANNELS > 2 ? 1.0f : 0.0f,
                    CLW_CHANNELS > 3 ? 1.0f : 0.0f);
    if (x < layer.x && y < layer.y)
        fb[layer.w + y * layer.x + x] += acc;
#endif
}
