"""Fine-level B-spline grids: the kept wavelet coefficients expanded on the device.

The thresholded wavelet expansion of a channel group equals one B-spline expansion at
level 0 (a change of basis, docs/model.md §4): ``f(x) = sum_i c_i N_j(x - i)`` in the group's
fine-voxel coordinates.  :func:`fine_grids` runs the real-line inverse transform of
:meth:`WaveletVolume.fine_coefficients` with ``cl/raytrace/expand.cl``, one separable step per
axis and level, so nothing is cropped and a 256^3 RGBA volume takes well under a second.
Channels go to their own float4 slot (R, G, B, A = channels 0..3), so the grids of
several groups add up to the full field.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl.array as cla
from pyopencl.elementwise import ElementwiseKernel
from pyopencl import cltypes

from ..device import programs
from ..device.context import ComputeContext
from ..device.kernels import BUFFER, Kernel
from ..errors import DeviceMemoryError, InputError
from ..model.geometry import band_lattice
from .bounds import content_weights


def _part_args(name: str) -> tuple:
    """The arguments of one input part of ``synth_axis`` (cl/raytrace/expand.cl)."""
    return ((name, BUFFER), (f"{name}_start", cltypes.int4), (f"{name}_shape", cltypes.int4),
            (f"{name}_taps", BUFFER), (f"n{name}", np.int32), (f"{name}_shift", np.int32))


_SYNTH_AXIS = Kernel("synth_axis", ("out", BUFFER), ("out_start", cltypes.int4), ("out_shape", cltypes.int4),
                     *_part_args("a"), *_part_args("b"), ("has_b", np.int32))


@dataclass
class FineGrid:
    """One group's coefficients ``c[i]`` of ``N_j(x - (start + i))`` on the device, float4 per point."""

    data: cla.Array        # (Z, Y, X, 4) float32, channels in their own slots
    start: tuple           # (z, y, x) fine index of data[0, 0, 0]
    shape: tuple           # (Z, Y, X)
    order: int             # B-spline order j
    channels: tuple        # the volume channels this grid carries

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * 16


@dataclass
class _Part:
    data: cla.Array
    start: np.ndarray  # (z, y, x)
    shape: np.ndarray

    def box(self, axis, taps, shift):
        """First and last child index this part reaches along ``axis`` through ``taps``."""
        lo = 2 * self.start[axis] + shift
        return lo, 2 * (self.start[axis] + self.shape[axis] - 1) + shift + len(taps) - 1


def fine_grids(wv, cc: ComputeContext, pad: int = 0, dense=None) -> tuple[list, float]:
    """Every group's fine grid, with ``pad`` zero points around it; returns ``(grids, seconds)``.

    ``dense``: each group's :meth:`ChannelGroup.dense_bands`, when the caller has them already.

    Raises :class:`DeviceMemoryError` before allocating when the device cannot hold them.
    """
    if wv.channels > 4:
        raise InputError(f"the ray tracer takes at most 4 channels (RGBA), this volume has {wv.channels}")
    need = _bytes_needed(wv, pad)
    if need > cc.info.global_mem * 0.8 or need / 2 > cc.info.max_alloc:
        raise DeviceMemoryError(
            f"expanding this volume to fine B-spline grids needs about {need / 2**20:.0f} MiB on "
            f"{cc.info.name}, which has {cc.info.global_mem / 2**20:.0f} MiB "
            f"({cc.info.max_alloc / 2**20:.0f} MiB per buffer); use fewer levels, crop the volume or pick "
            f"another --device")
    kernels = [programs.build(cc, ["raytrace/expand.cl"], dict(CLW_AXIS=a)) for a in range(3)]  # compile apart
    start = time.perf_counter()
    dense = dense if dense is not None else [g.dense_bands() for g in wv.groups]
    grids = [_expand_group(wv, g, bands, cc, kernels, pad) for g, bands in zip(wv.groups, dense)]
    if wv.content_mask is not None:
        clamp = ElementwiseKernel(cc.ctx, "float *grid, const uchar *keep", "if (!keep[i / 4]) grid[i] = 0.0f",
                                  "clamp_to_content")
        for grid in grids:  # docs/raytracing.md §4
            clamp(grid.data.reshape(-1), cla.to_device(cc.queue, content_weights(wv.content_mask, grid.start,
                                                                                 grid.shape).astype(np.uint8)))
    cc.queue.finish()
    return grids, time.perf_counter() - start


def _bytes_needed(wv, pad) -> int:
    """Peak device memory: the bands of one group plus two full-size fine boxes."""
    margin = max((g.wavelet.support("d") + 1) * 2 ** wv.levels for g in wv.groups) + 2 * pad
    box = int(np.prod([n + 2 * margin for n in wv.shape]))
    return 16 * (int(np.prod(wv.shape)) + 2 * box)


def _upload(cc, arr, channels) -> cla.Array:
    out = np.zeros(arr.shape[:3] + (4,), np.float32)
    out[..., list(channels)] = arr
    return cla.to_device(cc.queue, out)


def _expand_group(wv, g, dense, cc, kernels, pad) -> FineGrid:
    wav = g.wavelet
    taps = {"a": (wav.p / np.sqrt(2.0)).astype(np.float32), "d": (wav.q / np.sqrt(2.0)).astype(np.float32)}
    d_taps = {k: cla.to_device(cc.queue, v) for k, v in taps.items()}
    shifts = {k: wav.synthesis_shift(k) for k in "ad"}
    approx = _Part(_upload(cc, dense[0], g.channels), np.zeros(3, np.int64), np.array(dense[0].shape[:3]))
    by_level = {}
    for band, arr in zip(g.bands[1:], dense[1:]):
        if np.any(arr):  # an all-zero band adds nothing: skip it
            part = _Part(_upload(cc, arr, g.channels), np.zeros(3, np.int64), np.array(arr.shape[:3]))
            by_level.setdefault(band.level, {})[band.key] = part
        else:
            by_level.setdefault(band.level, {})
    crop = _nonzero_box(wav, g.bands, dense, pad)
    for m in range(wv.levels, 0, -1):
        parts = {"aaa": approx, **by_level.get(m, {})}
        for axis in range(3):  # array axis z, y, x; keys lose their leading letter per axis done
            merged = {}
            for rest in sorted({key[1:] for key in parts}):
                pair = [(letter, parts[letter + rest]) for letter in "ad" if letter + rest in parts]
                merged[rest] = _synth_axis(cc, kernels[2 - axis], pair, axis, d_taps, taps, shifts,
                                           crop[:, axis] if m == 1 else None)
            parts = merged
        approx = parts[""]
    if wv.levels == 0 and pad:
        approx = _padded(cc, approx, pad)
    return FineGrid(approx.data, tuple(int(s) for s in approx.start), tuple(int(s) for s in approx.shape),
                    wav.order, g.channels)


def _nonzero_box(wav, bands, dense, pad) -> np.ndarray:
    """(2, 3) first and last fine index, per array axis, that can hold a non-zero coefficient, widened by pad.

    A basis function refines into fine B-splines lying inside its support, so only indices i
    with [i, i + j] inside the union of the kept non-zero supports can be non-zero.
    """
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for band, arr in zip(bands, dense):
        nz = np.argwhere(np.any(arr != 0, axis=3))
        if len(nz) == 0:
            continue
        offset, step, support = band_lattice(wav, band.key, band.level)
        lo = np.minimum(lo, offset + step * nz.min(axis=0))
        hi = np.maximum(hi, offset + step * (nz.max(axis=0) + support))
    if not np.isfinite(lo).all():
        return np.zeros((2, 3), np.int64)
    return np.array([lo - pad, hi - wav.order + pad], np.int64)


def _synth_axis(cc, kernels, pair, axis, d_taps, taps, shifts, crop) -> _Part:
    """One synthesis step along array ``axis`` of an ('a', part) / ('d', part) pair.

    ``crop`` (first, last) bounds the output along ``axis`` (the last level: fine indices).
    """
    ends = [p.box(axis, taps[letter], shifts[letter]) for letter, p in pair]
    lo = np.min([p.start for _, p in pair], axis=0)
    hi = np.max([p.start + p.shape for _, p in pair], axis=0)
    lo[axis], hi[axis] = min(e[0] for e in ends), max(e[1] for e in ends) + 1
    if crop is not None:
        lo[axis], hi[axis] = crop[0], crop[1] + 1
    shape = hi - lo
    out = cla.empty(cc.queue, tuple(int(s) for s in shape) + (4,), np.float32)
    parts = {}
    for name, (letter, p) in zip("ab", pair + pair[:1] * (2 - len(pair))):  # a lone part twice, the second ignored
        parts.update({name: p.data, f"{name}_start": p.start[::-1], f"{name}_shape": p.shape[::-1],
                      f"{name}_taps": d_taps[letter], f"n{name}": len(taps[letter]), f"{name}_shift": shifts[letter]})
    _SYNTH_AXIS(kernels, cc.queue, tuple(int(s) for s in shape[::-1]), None, parts, out=out, out_start=lo[::-1],
                out_shape=shape[::-1], has_b=len(pair) == 2)
    return _Part(out, lo, shape)


def _padded(cc, part: _Part, pad: int) -> _Part:
    host = np.pad(part.data.get(), [(pad, pad)] * 3 + [(0, 0)])
    return _Part(cla.to_device(cc.queue, host), part.start - pad, np.array(host.shape[:3]))


def int4_xyz(zyx):
    """(z, y, x) -> OpenCL int4 (x, y, z, 0)."""
    z, y, x = (int(v) for v in zyx)
    return cltypes.make_int4(x, y, z, 0)
