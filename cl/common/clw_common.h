/* clw_common.h: constants shared by every clwave kernel.
 * CLW_SRC_HASH is set by the host (clwave/device/programs.py) so cached binaries follow the sources. */
#ifndef CLW_COMMON_H
#define CLW_COMMON_H

#ifndef CLW_SRC_HASH
#define CLW_SRC_HASH 0
#endif

/* The constants shared with the host (clwave/device/constants.py) come as build defines:
 * CLW_TILE (splat image tiles, pixels), CLW_MAX_LIGHTS, CLW_BLOCK and CLW_SUPER_CELLS (the edges of the
 * ray tracer's blocks and superblocks, in fine cells). */
#if !defined(CLW_TILE) || !defined(CLW_MAX_LIGHTS) || !defined(CLW_BLOCK) || !defined(CLW_SUPER_CELLS)
#error "build with the shared constants of clwave/device/constants.py (clwave.device.programs.build)"
#endif

/* Integer stages must equal their NumPy references exactly: no fused multiply-add. */
#pragma OPENCL FP_CONTRACT OFF

#endif
