/* raster_gpu.cl: splat_accumulate for GPUs: CLW_PX consecutive pixels of a row per work-item (1:
 * one pixel each), work-item l owning those of row l / (CLW_TILE / CLW_PX), a work-group of
 * CLW_TILE^2 / CLW_PX items per tile, the tile's splats in batches of CLW_BATCH through local memory. */
#include "splat/raster.h"
#ifndef CLW_PX
#error "build with CLW_PX, the pixels per work-item (clwave.splat.stages.GPU_PIXELS)"
#endif
#ifndef CLW_BATCH
#define CLW_BATCH 64
#endif

#define CLW_ITEMS_PER_ROW (CLW_TILE / CLW_PX)
__kernel void splat_accumulate(ACCUMULATE_PARAMS)
{
    __local int4 l_box[CLW_BATCH];
    __local int4 l_addr[CLW_BATCH];
    __local float4 l_f[CLW_BATCH];
    __local float4 l_w[CLW_BATCH];
    __local float2 l_cell[CLW_BATCH];

    const int tile = first_tile + get_global_id(0) / get_local_size(0);
    const int lid = get_local_id(0);
    const int nitems = get_local_size(0);
    int2 origin;
    const int4 layer = tile_layer(tile, layer_count, layers, &origin);
    const int width = layer.x, height = layer.y;
    fb += layer.w;
    const int4 corner = (int4)(origin, origin);
    const int y = corner.y + lid / CLW_ITEMS_PER_ROW;
    const int xbase = corner.x + (lid % CLW_ITEMS_PER_ROW) * CLW_PX;
    float4 acc[CLW_PX];
    for (int p = 0; p < CLW_PX; ++p)
        acc[p] = (float4)(0.0f);

    const uint2 r = ranges[tile];
    for (uint b0 = r.x; b0 < r.y; b0 += CLW_BATCH) {
        const uint nb = min((uint)CLW_BATCH, r.y - b0);
        for (uint k = lid; k < nb; k += nitems) {
            int4 a, bx;
            float4 f, w;
            float2 cen, cs;
            const int tex = splat_unpack(records + (b0 + k) * CLW_RECORD, &cen, &bx, &w);
            splat_lookup(tex_int[tex], tex_map[tex], cen, &a, &f, &cs);
            l_addr[k] = a;
            l_f[k] = f;
            l_cell[k] = cs;
            l_box[k] = corner + bx;
            l_w[k] = w;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (uint k = 0; k < nb; ++k) {
            const int4 bx = l_box[k];
            const int x0 = max(bx.x, xbase), x1 = min(bx.z, xbase + CLW_PX - 1);
            if (y < bx.y || y > bx.w || x0 > x1)
                continue;
            const int4 a = l_addr[k];
            const float4 f = l_f[k];
            const float2 cs = l_cell[k];
            float fv;
            const int row = splat_row(a, f, y, &fv);
            __global const float *r00 = texels + a.x + row;
            __global const float *r01 = texels + a.y + row;
            for (int x = x0; x <= x1; ++x) {
                float sample;
                if (a.w & 1) {
                    sample = (1.0f - fv) * ((1.0f - f.x) * r00[x] + f.x * r01[x])
                           + fv * ((1.0f - f.x) * r00[x + a.z] + f.x * r01[x + a.z]);
                } else if (a.w & 4) {  /* u coarser than the pixel: this pixel's two texels, the position
                                        * clamped to the margins first (raster_cpu.cl) */
                    const float tu = clamp(f.x + ((float)x - cs.x) * cs.y, -1.0f, (float)a.y);
                    const int col = min((int)floor(tu), a.y - 1);
                    const float fu = tu - (float)col;
                    sample = (1.0f - fv) * ((1.0f - fu) * r00[col] + fu * r00[col + 1])
                           + fv * ((1.0f - fu) * r00[col + a.z] + fu * r00[col + 1 + a.z]);
                } else {
                    const int col = clamp((int)floor(cell_position(f.x + ((float)x - cs.x) * cs.y, cs.y)), -1, a.y);
                    sample = (1.0f - fv) * r00[col] + fv * r00[col + a.z];
                }
                acc[x - xbase] += l_w[k] * sample;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (y >= height)
        return;
    for (int p = 0; p < CLW_PX; ++p)
        if (xbase + p < width)
            fb[y * width + xbase + p] += acc[p];
}
