"""What the staged tracer's coarse stage reads of a ``.clw`` file besides its approximation, without a coefficient
more (docs/raytracing.md §8-§9, docs/chunked.md §4): the energy of the details it lacks, as a field (written with
the file, :mod:`.detail_field`) or from the tiers' run tables (a file written before it), and the occupancy of the
approximation's coefficients, the file's summary of the content mask."""

from __future__ import annotations

import numpy as np

from ..model.bspline import SplineWavelet
from ..model.chunked import TIER_SHIFT, tier_energy
from ..model.transform import band_layout
from .clw import open_clw
from .clw_header import check_dataset, checked_header


def detail_energy(path) -> float:
    """The sum of the squared importances (``|c| ||basis||``, :func:`~clwave.model.wavelet.band_importance`) of
    a ``.clw`` file's stored details, from its tiers' run tables alone (a few kilobytes, no coefficient read):
    each counted at its tier's geometric middle squared, within ``9/8`` of its importance squared
    (:func:`~clwave.model.chunked.tier_energy`).  What the approximation alone leaves out (docs/raytracing.md §9)."""
    energy = 0.0
    with open_clw(path) as (h5, header):
        for gi in range(len(checked_header(header)[3])):
            runs = h5.get(f"g{gi}/runs")
            check_dataset(runs, (runs.shape[0] if runs is not None else -1, 3), np.int64)
            runs = runs[...]
            runs = runs[(runs[:, 0] >= 0) & (runs[:, 0] < 1 << (32 - TIER_SHIFT - 1))]  # details, finite tiers
            energy += float(np.sum(runs[:, 2] * tier_energy(runs[:, 0])))
    return energy


def detail_levels(path, tiered=None) -> tuple | None:
    """A ``.clw`` file's stored details' energy in two parts: the coarsest level's field energy and the finer levels'
    importance energy (the tiers' less the coarsest level's as they count it); None where a
    group lacks the figure (a file written before it)."""
    energy = detail_energy(path) if tiered is None else tiered
    # the figures count the coarsest level from the run table's own tiers (:mod:`.detail_field`): together at most
    # the table's sum, the margin for float rounding only
    most, coarsest, field = energy * (1 + 1e-9), 0.0, 0.0
    with open_clw(path) as (h5, header):
        for gi in range(len(checked_header(header)[3])):
            data = h5.get(f"g{gi}/detail_field")
            if data is None:
                return None
            check_dataset(data, (2,), np.float64)
            figure = data[...]
            if not np.all(np.isfinite(figure) & (figure >= 0)):
                raise ValueError(f"member {data.name} holds {figure.tolist()}, not two finite energies >= 0")
            coarsest += figure[1]
            field += figure[0]
            if coarsest > most or not np.isfinite(field):
                raise ValueError(f"member {data.name} holds {figure.tolist()}, more energy than the file's tiers "
                                 f"({most:.6g})")
    return float(field), max(float(energy - coarsest), 0.0)  # not below 0 by float rounding


def approximation_occupancy(path) -> list:
    """Per channel group of a ``.clw`` file, bool (the approximation band's shape): which coefficients of its
    coarsest approximation the content occupies (:class:`~clwave.io.occupancy.OccupancyGrid`), checked against the
    header; None where the file has no such summary (written before it, or without a content mask)."""
    with open_clw(path) as (h5, header):
        shape, levels, _, groups = checked_header(header)
        out = []
        for gi, g in enumerate(groups):
            data, band = h5.get(f"g{gi}/occupancy"), band_layout(SplineWavelet(g["wavelet"]), shape, levels)[0].shape
            if data is not None:
                check_dataset(data, (*band[:2], -(-band[2] // 8)), np.uint8)
            out.append(None if data is None else np.unpackbits(data[...], axis=2, count=band[2]).view(bool))
    return out
