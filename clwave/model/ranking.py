"""Coefficients in importance order (the paper's §5.2 ranking): the order :meth:`WaveletVolume.ranked
<clwave.model.wavelet.WaveletVolume.ranked>` gives and the splat renderer draws in, and the one table made in it, a
block of rows at a time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..io.progress import progress


@dataclass
class RankedTable:
    """A group's coefficients in an order (by importance, or a prefix's first: :func:`by_importance`), packed as the
    splatting kernels read them (``cl/splat/bin.cl``), so that the renderer holds one table for the host and the
    device (docs/splatting.md §6): ``coef`` (K, 4) int32 ``(k_x, k_y, k_z, band)``, band the :attr:`Band.id
    <clwave.model.transform.Band.id>`, and ``packed`` (K, 4) float32 values, the channels beyond the group's
    ``channels`` zero; ``importance`` (K,) float32 of each row where it was asked for
    (:meth:`~clwave.model.wavelet.WaveletVolume.ranked`), else None (the kernels do not read it)."""

    coef: np.ndarray
    packed: np.ndarray
    channels: int
    importance: np.ndarray | None = None

    @property
    def index(self) -> np.ndarray:
        """(K, 3) ``(k_z, k_y, k_x)``, the pywt index in array order, a view."""
        return self.coef[:, 2::-1]

    @property
    def band(self) -> np.ndarray:
        """(K,) band ids, level * 8 + subband code (code 0: the approximation), :attr:`Band.id
        <clwave.model.transform.Band.id>`, a view."""
        return self.coef[:, 3]

    @property
    def values(self) -> np.ndarray:
        """(K, C) the group's channels, a view."""
        return self.packed[:, :self.channels]


#: rows :func:`ranked_table` makes at a time: the band lookup's int64 work arrays (about 60 bytes a row) stay small
#: beside the table made from them
RANK_ROWS = 1 << 20
_LOW = np.uint64(0xFFFFFFFF)


def by_importance(importance, first=None) -> np.ndarray:
    """Indices (uint32) of ``importance`` (float32 >= 0, a group's in its ascending position order) by decreasing
    importance, ties by position: the importance order of :meth:`WaveletVolume.ranked`; with ``first`` (indices),
    those in that order, then the others in that order (a file's prefix first, docs/viewer.md §2).  One sort of
    64-bit keys, the importance's bits inverted (a float >= 0 orders as its bits) over the index: NumPy sorts those
    with its vector sort, faster than a stable argsort of the importance.  The inverted bits of a float >= 0 have
    their top bit set; clearing it in the keys of ``first`` puts those before every other.  The keys are made
    and sorted in place: 12 bytes a coefficient at the most beside ``importance`` (docs/viewer.md §2)."""
    n = len(importance)
    if n >= 1 << 32:
        raise InputError(f"a group of {n:,} coefficients is more than ranking takes (2^32)")
    keys = np.asarray(importance, np.float32).view(np.uint32).astype(np.uint64)
    keys ^= _LOW
    keys <<= np.uint64(32)
    if first is not None:
        keys[first] &= np.uint64((1 << 63) - 1)
    for lo in range(0, n, RANK_ROWS):
        keys[lo:lo + RANK_ROWS] |= np.arange(lo, min(n, lo + RANK_ROWS), dtype=np.uint64)
    keys.sort()
    keys &= _LOW
    return keys.astype(np.uint32)


def ranked_table(group, order, importance=None, each_block=None) -> RankedTable:
    """The kept coefficients ``order`` (indices into its ascending positions) of ``group`` (a
    :class:`~clwave.model.wavelet.ChannelGroup`) as a :class:`RankedTable` in that order, with the ``importance`` of
    each of its positions where given.  Made a block of :data:`RANK_ROWS` rows at a time (the band numbers and
    indices of :meth:`~clwave.model.wavelet.ChannelGroup.locate`): no table but this one, and no float64 copy of the
    values; ``each_block(lo, band_no)``, where given, is called once the block of rows from lo is filled, with their
    band numbers."""
    n, channels = len(order), len(group.channels)
    ids = np.array([b.id for b in group.bands], np.int32)
    table = RankedTable(np.empty((n, 4), np.int32), np.zeros((n, 4), np.float32), channels,
                        None if importance is None else np.take(importance, order).astype(np.float32, copy=False))
    positions = group.all_positions()
    for lo in progress(range(0, n, RANK_ROWS), desc="ranked table"):
        hi = min(n, lo + RANK_ROWS)
        band_no, index = group.locate(positions[order[lo:hi]])
        table.coef[lo:hi, :3], table.coef[lo:hi, 3] = index[:, ::-1], ids[band_no]
        for ch in range(channels):
            table.packed[lo:hi, ch] = np.take(group.values[ch], order[lo:hi])
        if each_block is not None:
            each_block(lo, band_no)
    return table
