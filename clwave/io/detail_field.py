"""The energy of a ``.clw`` file's coarsest details as a field, written with the file (``g<i>/detail_field``,
docs/chunked.md §4) for the staged tracer's coarse frames, which read no detail (docs/raytracing.md §9).

The tier table gives the details' importance energy ``sum |c|² ||psi||²``, the field's energy only where the
functions are orthogonal; the CDF synthesis wavelets are not, and a model's details overlap and cancel (measured in
docs/known-gaps.md §9). The coarsest level's seven detail bands, each about 1/512 of the voxels at three levels
(with the B-splines' margin, 1.7 % of them in all at 1024³) and most of the details' importance energy, are held
whole while the file is written and synthesized at the end to the approximation coefficients of level L - 1 (their
field), whose energy is ``<c, c * G>`` (the B-splines' Gram filter,
:func:`~clwave.raytrace.coarse_estimate.field_energy`); the finer levels, whose bands are as large as the volume,
keep their importance energy from the tiers. The figure per group is ``(field energy of level L's details, their
importance energy as the tier table counts it)``, the first in the importances' convention (the largest channel: the
field's energy, channels summed, times the bands' importance energy over their plain ``sum |c|² ||psi||²``), so that
a reader takes the details' energy as the tier table's less the second plus the first. The second is counted from
the tiers the run table holds (those of the values before quantisation), so that it is the tier table's own count of
that level; the first from the stored coefficients as a reader gets them back (quantised values rounded). Both depend
on those alone, not on the order they come in: the in-memory and the streamed writers write the same file.
"""

from __future__ import annotations

import numpy as np
import pywt

from ..model.bspline import SplineWavelet
from ..model.chunked import tier_energy
from ..model.transform import band_layout
from ..model.wavelet import band_importance
from ..raytrace.coarse_estimate import field_energy


class DetailField:
    """Gathers a group's stored coefficients (:meth:`add`, a block at a time, in any order; each position once)
    into its figure (:meth:`figure`): the coarsest level's details in a dense float32 array (C, 7 bands' size) and
    their tiers in a dense int16 one (-1 where nothing is stored)."""

    def __init__(self, wavelet: SplineWavelet, shape, levels: int):
        self.wavelet, self.bands = wavelet, band_layout(wavelet, shape, levels)
        self.coarsest = self.bands[1:8]  # level L's seven detail bands, contiguous in the layout
        self.lo, self.hi = self.coarsest[0].start, self.coarsest[-1].start + self.coarsest[-1].size
        self.dense = None
        self.tiers = np.full(self.hi - self.lo, -1, np.int16)

    def add(self, positions, values, tiers):
        """Stored coefficients ``positions`` (n,) of the group's layout, their ``values`` (C, n) as a reader gets
        them back, and their ``tiers`` (n,) as the run table holds them."""
        if self.dense is None:
            self.dense = np.zeros((values.shape[0], self.hi - self.lo), np.float32)
        coarsest = (positions >= self.lo) & (positions < self.hi)
        self.dense[:, positions[coarsest] - self.lo] = values[:, coarsest]
        self.tiers[positions[coarsest] - self.lo] = tiers[coarsest]

    def figure(self) -> np.ndarray:
        """float64 (2,): the field energy of the coarsest level's details and their importance energy as the tier
        table counts it (each stored coefficient at its tier's geometric middle, as
        :func:`~clwave.io.summary.detail_energy` counts the runs)."""
        if self.dense is None:  # nothing stored
            return np.zeros(2)
        size, shape = self.coarsest[0].size, self.coarsest[0].shape
        importance = plain = tiered = field = 0.0
        for i, band in enumerate(self.coarsest):
            part = self.dense[:, i * size:(i + 1) * size]
            imp = band_importance(self.wavelet, band, part, None, None, None)
            importance += float(np.sum(imp.astype(np.float64) ** 2))
            tiers = self.tiers[i * size:(i + 1) * size]
            tiered += float(np.sum(tier_energy(tiers[tiers >= 0])))
            norm = np.prod([self.wavelet.norm(letter) for letter in band.key])
            plain += float(np.sum(np.square(part, dtype=np.float64))) * norm ** 2
        # pywt's synthesis (the model's, docs/model.md §4) crops (rec_len - 2) / 2 of its output at each end: zeros
        # padded to the bands, half of rec_len on each side, so that it crops nothing of the field
        half = self.wavelet.pywt.rec_len // 2
        zero = np.zeros(np.add(shape, 2 * half), np.float32)
        for channel in self.dense:  # a channel at a time: level L - 1's grid is 8 times the bands' size; in float32,
            parts = {band.key: np.pad(channel[i * size:(i + 1) * size].reshape(shape), half)  # summed in float64
                     for i, band in enumerate(self.coarsest)}
            grid = pywt.idwtn(dict(parts, aaa=zero), self.wavelet.pywt, mode="zero", axes=(0, 1, 2))
            field += field_energy(grid[None], self.wavelet.order)
        return np.array([field * importance / plain if plain > 0 else 0.0, tiered])
