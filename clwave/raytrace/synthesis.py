"""The expansion's synthesis steps on the device (``cl/raytrace/expand.cl``, docs/raytracing.md §3): one separable step
along one axis of a pair of parts, each a dense box of :func:`lanes` floats a coefficient, for
:mod:`clwave.raytrace.bricks`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl.array as cla
from pyopencl import cltypes

from ..device import programs
from ..device.kernels import BUFFER, Kernel


def _part_args(name: str, taps: str) -> tuple:
    """The arguments of one input part of ``synth_axis`` (cl/raytrace/expand.cl)."""
    return ((name, BUFFER), (f"{name}_start", cltypes.int4), (f"{name}_shape", cltypes.int4), (taps, BUFFER),
            (f"{name}_shift", np.int32), (f"has_{name}", np.int32))


_SYNTH_AXIS = Kernel("synth_axis", ("out", BUFFER), ("out_start", cltypes.int4), ("out_shape", cltypes.int4),
                     *_part_args("a", "h"), *_part_args("d", "g"))


def lanes(g) -> int:
    """Floats a coefficient of group ``g``'s synthesis (``CLW_LANES`` of ``cl/raytrace/expand.cl``): its channels in
    their slots of a float4, or a group of one channel's alone (a scalar model's synthesis a quarter of the work)."""
    return 1 if len(g.channels) == 1 else 4


#: work-group of the expansion's 3-D launches: one size for every box, so that PoCL compiles each kernel once
#: (it specialises a kernel per work-group size, and picks a new one for many a global size)
GROUP = (8, 8, 1)


def whole_groups(size) -> tuple:
    """A 3-D global size rounded up to whole :data:`GROUP` work-groups (the kernels skip what lies beyond)."""
    return tuple(-(-int(n) // g) * g for n, g in zip(size, GROUP))


class Synthesis:
    """The synthesis programs (``cl/raytrace/expand.cl``), one per order, axis and :func:`lanes`, built once: a model
    expanded at its coarsest level alone (the staged set-up's first stage) synthesises nothing and builds none."""

    def __init__(self, cc):
        self.cc, self.built = cc, {}

    def kernels(self, group, axis):
        wavelet = group.wavelet
        key = (wavelet.order, axis, lanes(group))
        if key not in self.built:
            self.built[key] = programs.build(self.cc, ["raytrace/expand.cl"], dict(
                CLW_AXIS=axis, CLW_NH=len(wavelet.p), CLW_NG=len(wavelet.q), CLW_LANES=key[2]))
        return self.built[key]


@dataclass
class Part:
    data: cla.Array
    start: np.ndarray  # (z, y, x)
    shape: np.ndarray


def synth_axis(cc, kernels, pair, axis, d_taps, shifts, crop) -> Part:
    """One synthesis step along array ``axis`` of an ('a', part) / ('d', part) pair (either may be missing), the
    output cropped to the child indices ``crop`` (first, last) along ``axis``."""
    lo = np.min([p.start for _, p in pair], axis=0)
    hi = np.max([p.start + p.shape for _, p in pair], axis=0)
    lo[axis], hi[axis] = crop[0], crop[1] + 1
    shape = hi - lo
    out = cla.empty(cc.queue, tuple(int(s) for s in shape) + pair[0][1].data.shape[3:], np.float32)
    given, any_part = dict(pair), pair[0][1]  # a missing part is flagged, its buffer any of the given
    parts = {}
    for name, taps in (("a", "h"), ("d", "g")):
        p = given.get(name, any_part)
        parts.update({name: p.data, f"{name}_start": p.start[::-1], f"{name}_shape": p.shape[::-1],
                      taps: d_taps[name], f"{name}_shift": shifts[name], f"has_{name}": name in given})
    size = shape[::-1].copy()
    if out.ndim == 3 and axis != 2:  # one float a coefficient along y or z: four outputs a work-item (CLW_X4)
        size[0] = -(-size[0] // 4)
    _SYNTH_AXIS(kernels, cc.queue, whole_groups(size), GROUP, parts, out=out, out_start=lo[::-1],
                out_shape=shape[::-1])
    return Part(out, lo, shape)
