"""The ray tracer's wavelet field (``field="wavelet"``, docs/raytracing.md §4): the model's kept coefficients in
dense bands with the tables ``cl/raytrace/field_wavelet.h`` sums them from along each ray (per-ray active lists, the
paper's §3.3 reference), and the field's bounds for empty-space skipping, made from the coefficients."""

from __future__ import annotations

import time

import numpy as np
import pyopencl.array as cla

from ..device.constants import BLOCK
from ..device.memory import check_buffer
from ..errors import DeviceMemoryError
from ..model.bspline import piece_polynomials
from ..model.geometry import band_lattice
from ..threads import checkpoint
from .bounds import block_sums, cell_blocks, clip_box, content_cells, superblocks
from .bricks import group_defines

WAVELET_GROUP = 8  # rays per work-group with the wavelet field


class WaveletField:
    """What a :class:`~clwave.raytrace.tracer.RayTracer` of the wavelet field holds of model ``wv`` on the device of
    ``cc`` (within ``budget``): the dense bands and their tables (``field_tables``), the block bounds and their
    superblocks, the clip box and the content cells the march is clamped to, and the build options (``defines``,
    ``local_size``) for a ray's ``active`` list of at most that many entries; ``orders``, each group's B-spline
    order.  ``abandon``: given up between two bands (:func:`~clwave.threads.checkpoint`).

    A block's bound is the sum over the coefficients whose supports meet it of |c| 2^{-3m/2} times the product of
    the prototypes' maxima along the axes (N_j peaks at j/2; |psi| <= max |q_k| by the partition of unity), so it
    bounds every channel of the field there.
    """

    def __init__(self, wv, cc, budget, active, orders, abandon=None):
        dense = [g.dense_bands() for g in wv.groups]
        q, start = cc.queue, time.perf_counter()
        j0 = orders[0]
        values, info, shape, lo, weights, offset = [], [], [], [], [], 0
        for g, group_dense in zip(wv.groups, dense):
            wav = g.wavelet
            shift = (j0 - wav.order) / 2.0  # grid-0 fine coordinates (docs/raytracing.md §3: lattices of both parities)
            peak = {"a": float(wav.phi(wav.order / 2.0)), "d": float(np.max(np.abs(wav.q)))}
            for band, arr in zip(g.bands, group_dense):
                checkpoint(abandon)
                key_xyz = band.key[::-1]
                flat = np.zeros(arr.shape[:3] + (4,), np.float32)
                flat[..., list(g.channels)] = arr * 2.0 ** (-1.5 * band.level)
                values.append(flat.reshape(-1, 4))
                psi_bits = sum(1 << a for a, letter in enumerate(key_xyz) if letter == "d")
                info.append((band.level, psi_bits, wav.order, offset))
                shape.append((*arr.shape[2::-1], 0))
                band_offset, step, _ = band_lattice(wav, band.key, band.level)
                lo.append([*(band_offset[::-1] + shift), step])
                weights.append(np.abs(flat).max(axis=3) * np.prod([peak[letter] for letter in band.key]))
                offset += arr[..., 0].size
        if offset >= 2 ** 31:
            raise DeviceMemoryError(f"{offset} wavelet coefficients are more than the wavelet field indexes "
                                    f"(2^31); use field='bspline'")
        coef = np.concatenate(values)
        check_buffer(cc, coef.nbytes, "the dense bands", "use field='bspline' or a smaller volume", budget, share=0.5)
        bound, self.occ_origin, _ = block_sums(wv, weights)
        bound = self._empty_space(wv, cc, bound)
        self.block_bound = cla.to_device(q, bound.astype(np.float32))
        self.q_bound = float(bound.max())
        self.occupied_fraction = float(np.mean(bound > 0))
        self.poly = piece_polynomials()
        self.field_tables = dict(coef=cla.to_device(q, coef), info=cla.to_device(q, np.array(info, np.int32)),
                                 shape=cla.to_device(q, np.array(shape, np.int32)),
                                 band_lo=cla.to_device(q, np.array(lo, np.float32)))
        self.defines = dict(CLW_WAVELET=None, CLW_BANDS=len(info), CLW_ACTIVE=active, **group_defines(orders))
        # PoCL keeps a work-group's private active lists on one thread's stack: small groups
        self.local_size = (WAVELET_GROUP, 1)
        self.setup_seconds = time.perf_counter() - start
        self.super_bound_host, self.super_origin = superblocks(self.block_bound.get(), self.occ_origin)
        self.super_bound = cla.to_device(q, self.super_bound_host)

    def _empty_space(self, wv, cc, blocks):
        """Clear the blocks (bounds or occupancy) that no content of the source volume reaches, keep the
        reached cells for the march (``self.content``, per grid-0 cell of the blocks' box), and set the
        clip box (docs/raytracing.md §4)."""
        origin, shape = np.asarray(self.occ_origin) * BLOCK, np.array(blocks.shape) * BLOCK
        cells = content_cells(wv, origin, shape)
        if cells is not None:
            blocks = blocks * cell_blocks(cells).astype(blocks.dtype)
        self.box = clip_box(blocks, self.occ_origin)
        self.content_origin = origin
        self.content_cells = cells
        self.content = cla.to_device(cc.queue, np.ones(1, np.uint8) if cells is None else cells)
        self.content_shape = np.zeros(3, np.int64) if cells is None else shape  # 0: no content cells
        return blocks
