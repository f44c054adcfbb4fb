/* raster_cpu.cl: splat_accumulate for CPUs (PoCL): one work-item owns a tile and walks each splat's
 * rows in it, 16 pixels a float16 vector, with the splat's set-up done once per tile rather than
 * once per row (docs/splatting.md §3).  Grid: one work-item (and work-group) per tile. */
#include "splat/raster.h"

#if CLW_TILE != 16
#error "the per-tile kernel works in rows of 16 pixels"
#endif
/* texels a row of 16 pixels reads along u gathered (lookup bit 2, s_u < 1): columns c0 .. c0 + 15 and the last
 * lane's second */
#define CLW_GATHER_TEXELS 17
__kernel void splat_accumulate(ACCUMULATE_PARAMS)
{
    const int tile = first_tile + get_global_id(0);
    int2 corner;
    const int4 layer = tile_layer(tile, layer_count, layers, &corner);
    const int width = layer.x, height = layer.y, xbase = corner.x, ybase = corner.y;
    fb += layer.w;
    const float16 lane = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    float16 acc[CLW_CHANNELS][CLW_TILE];
    for (int ch = 0; ch < CLW_CHANNELS; ++ch)
        for (int i = 0; i < CLW_TILE; ++i)
            acc[ch][i] = 0.0f;

    const uint2 r = ranges[tile];
    for (uint k = r.x; k < r.y; ++k) {
        int4 bx, a;  /* bx: the splat's pixels in the tile */
        float4 w, f;
        float2 cen, cs;
        const int tex = splat_unpack(records + k * CLW_RECORD, &cen, &bx, &w);
        splat_lookup(tex_int[tex], tex_map[tex], cen, &a, &f, &cs);
        const float c[4] = {w.x, w.y, w.z, w.w};  /* per channel, indexed in the channel loops */
        const int y0 = ybase + bx.y, y1 = ybase + bx.w;
        /* all 16 lanes read (the pool has 16 zeros before and 32 after it), masked lanes drop */
        const float16 mask = select((float16)(0.0f), (float16)(1.0f),
                                    isgreaterequal(lane, (float16)(bx.x)) & islessequal(lane, (float16)(bx.z)));
        float fv;
        const int row0 = splat_row(a, f, y0, &fv);
        if (a.w == 3) {
            /* bilinear from phase planes: the texel step along v is P rows per pixel (an integer),
             * so the four weights are those of row y0 for every row */
            const float fu = f.x;
            const float16 w00 = mask * ((1.0f - fu) * (1.0f - fv)), w01 = mask * (fu * (1.0f - fv));
            const float16 w10 = mask * ((1.0f - fu) * fv), w11 = mask * (fu * fv);
            const int step = (int)f.w * a.z;
            __global const float *r0 = texels + a.x + row0 + xbase;
            __global const float *r1 = texels + a.y + row0 + xbase;
            for (int y = y0; y <= y1; ++y, r0 -= step, r1 -= step) {
                const float16 sample = fma(w00, vload16(0, r0), fma(w01, vload16(0, r1),
                                       fma(w10, vload16(0, r0 + a.z), w11 * vload16(0, r1 + a.z))));
                for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                    acc[ch][y - ybase] = fma((float16)(c[ch]), sample, acc[ch][y - ybase]);
            }
            continue;
        }
        if (a.w & 4) {
            /* u texels of more than a pixel (s_u < 1, a magnified view): 16 lanes span under 16 texels, so a lane's
             * sample is sum_k w_k t_k over the texels k of columns c0 .. c0 + K of a texel row (v interpolated),
             * its weights set once per splat (the same on every row); no gather, which PoCL does lane by lane.
             * Positions clamped to the margins [-1, a.y] first, the weight from the clamped column: beyond them a
             * lane reads zeros, not the edge texel */
            const float16 tu = clamp(f.x + (((float16)((float)xbase) + lane) - cs.x) * cs.y, -1.0f, (float)a.y);
            const int16 col = min(convert_int16(floor(tu)), (int16)(a.y - 1));
            const float16 fu = tu - convert_float16(col);
            const int c0 = col.s0, K = min(col.sf + 1 - c0, CLW_GATHER_TEXELS - 1);
            float16 wk[CLW_GATHER_TEXELS];
            for (int k = 0; k <= K; ++k)
                wk[k] = mask * (select((float16)(0.0f), 1.0f - fu, col == (int16)(c0 + k))
                                + select((float16)(0.0f), fu, col == (int16)(c0 + k - 1)));
            for (int y = y0; y <= y1; ++y) {
                const int row = splat_row(a, f, y, &fv);
                __global const float *t0 = texels + a.x + row + c0, *t1 = t0 + a.z;
                float16 sample = 0.0f;
                for (int k = 0; k <= K; ++k)
                    sample = fma(wk[k], (float16)((1.0f - fv) * t0[k] + fv * t1[k]), sample);
                for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                    acc[ch][y - ybase] = fma((float16)(c[ch]), sample, acc[ch][y - ybase]);
            }
            continue;
        }
        for (int y = y0; y <= y1; ++y) {  /* a cell axis (Haar along a world axis) */
            const int row = splat_row(a, f, y, &fv);
            __global const float *r00 = texels + a.x + row;
            float16 sample;
            if (a.w & 1) {
                __global const float *r01 = texels + a.y + row;
                sample = (1.0f - fv) * ((1.0f - f.x) * vload16(0, r00 + xbase) + f.x * vload16(0, r01 + xbase))
                       + fv * ((1.0f - f.x) * vload16(0, r00 + xbase + a.z) + f.x * vload16(0, r01 + xbase + a.z));
            } else {  /* u cells: each lane takes its nearest column (a.y of them, a handful: 2 for
                       * footprints), by selects rather than gathers; lanes off the texture keep 0 */
                const int16 col = convert_int16(floor(cell_position16(
                    f.x + (((float16)((float)xbase) + lane) - cs.x) * cs.y, cs.y)));
                sample = 0.0f;
                for (int q = 0; q < a.y; ++q) {
                    const float cell = (1.0f - fv) * r00[q] + fv * r00[q + a.z];
                    sample = select(sample, (float16)(cell), col == (int16)(q));
                }
            }
            for (int ch = 0; ch < CLW_CHANNELS; ++ch)
                acc[ch][y - ybase] = fma((float16)(c[ch]), mask * sample, acc[ch][y - ybase]);
        }
    }
    for (int i = 0; i < CLW_TILE && ybase + i < height; ++i) {
        float out[4][16] = {{0}};
        for (int ch = 0; ch < CLW_CHANNELS; ++ch)
            vstore16(acc[ch][i], 0, out[ch]);
        for (int p = 0; p < 16 && xbase + p < width; ++p)
            fb[(ybase + i) * width + xbase + p] += (float4)(out[0][p], out[1][p], out[2][p], out[3][p]);
    }
}
