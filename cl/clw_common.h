/* clw_common.h: constants and types shared by every clwave kernel.
 * CLW_SRC_HASH is set by the host (programs.py) so cached binaries follow the sources. */
#ifndef CLW_COMMON_H
#define CLW_COMMON_H

#ifndef CLW_SRC_HASH
#define CLW_SRC_HASH 0
#endif

#endif
