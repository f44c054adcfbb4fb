"""Constants the host and the kernels share, in one place.

Every program is built with :func:`defines` as ``-D`` options (:func:`clwave.device.programs.build`);
the kernel sources have no values of their own for these and refuse to build without them.
"""

TILE = 16        #: splat images are binned and accumulated in TILE x TILE pixel tiles (records keep 4 bits)
MAX_LIGHTS = 8   #: the ray tracer keeps its lights in private memory
BLOCK = 4        #: empty-space blocks of the ray tracer are BLOCK^3 fine cells
SUPER = 4        #: and its superblocks SUPER^3 blocks, crossed in one step where all are empty
BRICK = BLOCK * SUPER  #: fine cells along the edge of a ray-tracing brick (grid-0 coordinates)
#: pixels: a splat's cell lookup (Haar along a world axis) takes a pixel this near a cell edge as on it, so that
#: neighbouring splats, each rounding its own centre, agree on which one holds it (docs/splatting.md §1, "cells")
CELL_SNAP = 1e-3


def defines() -> dict:
    """The ``CLW_*`` build defines of the shared constants."""
    return dict(CLW_TILE=TILE, CLW_MAX_LIGHTS=MAX_LIGHTS, CLW_BLOCK=BLOCK, CLW_SUPER_CELLS=BLOCK * SUPER,
                CLW_CELL_SNAP=f"{CELL_SNAP!r}f")


def record_uint4s(channels: int, perspective: bool = False) -> int:
    """uint4s in the splat record of one (tile, splat) pair (``cl/splat/record.h``): the centre,
    texture and pixel box with the first channel's value, and a second uint4 for 2-4 channels or the
    depth of a perspective splat."""
    return 1 if channels == 1 and not perspective else 2
