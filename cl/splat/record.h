/* record.h: the record of one splat in one image tile, written by binning
 * (bin.cl) and read by accumulation (raster_cpu.cl, raster_gpu.cl).
 *
 * CLW_RECORD uint4s: (centre col, centre row, bits, c_0) and, with more than one channel,
 * (c_1, c_2, c_3, 0), floats as their bits (so the bits field never passes through a float).
 * bits: the texture id (bits 0-15) and the splat's pixels in the tile, x0, x1, y0, y1 in
 * 0..CLW_TILE - 1 (4 bits each from bit 16), inclusive.
 * Perspective builds (-DCLW_PERSPECTIVE, cl/splat/cone.cl) keep the splat's depth in the w of a second
 * uint4, always present there, and their centres are float4 (col, row, depth, 0).
 * Build: -DCLW_CHANNELS=C (1..4), the channels accumulated, and -DCLW_RECORD, the uint4s per record. */
#ifndef SPLAT_RECORD_H
#define SPLAT_RECORD_H
#include "common/clw_common.h"

#if !defined(CLW_CHANNELS) || !defined(CLW_RECORD)
#error "build with CLW_CHANNELS and CLW_RECORD (clwave.device.constants.record_uint4s)"
#endif
#if CLW_TILE > 16
#error "splat records keep tile pixels in 4 bits"
#endif

#ifdef CLW_PERSPECTIVE
#if CLW_RECORD != 2
#error "perspective records are 2 uint4s"
#endif
#define CLW_CENTRE float4
#define CLW_DEPTH(centre) (centre).z
#else
#define CLW_CENTRE float2
#define CLW_DEPTH(centre) 0.0f
#endif

/* box: the splat's pixel box (x0, y0, x1, y1) relative to the tile's corner */
inline void splat_record(__global uint4 *rec, const int4 box, const CLW_CENTRE centre, const int tex, const float4 c)
{
    const int4 clip = clamp(box, 0, CLW_TILE - 1);
    const uint bits = (uint)tex | (uint)clip.x << 16 | (uint)clip.z << 20 | (uint)clip.y << 24
                      | (uint)clip.w << 28;
    rec[0] = (uint4)(as_uint(centre.x), as_uint(centre.y), bits, as_uint(c.x));
#if CLW_CHANNELS > 1 || defined(CLW_PERSPECTIVE)
    rec[1] = as_uint4((float4)(c.y, c.z, c.w, CLW_DEPTH(centre)));
#endif
}

/* The texture id, centre, tile box (x0, y0, x1, y1) and channel values of a record */
inline int splat_unpack(__global const uint4 *rec, CLW_CENTRE *centre, int4 *box, float4 *c)
{
    const uint4 r0 = rec[0];
    const uint bits = r0.z;
    *box = (int4)(bits >> 16 & 15, bits >> 24 & 15, bits >> 20 & 15, bits >> 28);
#if CLW_CHANNELS > 1 || defined(CLW_PERSPECTIVE)
    const float4 r1 = as_float4(rec[1]);
    *c = (float4)(as_float(r0.w), r1.x, r1.y, r1.z);
#ifdef CLW_PERSPECTIVE
    *centre = (float4)(as_float2(r0.xy), r1.w, 0.0f);
#else
    *centre = as_float2(r0.xy);
#endif
#else
    *centre = as_float2(r0.xy);
    *c = (float4)(as_float(r0.w), 0.0f, 0.0f, 0.0f);
#endif
    return (int)(bits & 0xffff);
}
#endif
