/* clw_common.h: constants shared by every clwave kernel.
 * CLW_SRC_HASH is set by the host (programs.py) so cached binaries follow the sources. */
#ifndef CLW_COMMON_H
#define CLW_COMMON_H

#ifndef CLW_SRC_HASH
#define CLW_SRC_HASH 0
#endif

/* Image tiles are CLW_TILE x CLW_TILE pixels (splatting). */
#ifndef CLW_TILE
#define CLW_TILE 16
#endif

/* Integer stages must equal their NumPy references exactly: no fused multiply-add. */
#pragma OPENCL FP_CONTRACT OFF

#endif
