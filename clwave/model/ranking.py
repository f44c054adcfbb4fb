"""Coefficients in importance order (the paper's §5.2 ranking): the order :meth:`WaveletVolume.ranked
<clwave.model.wavelet.WaveletVolume.ranked>` gives and the tables made in it, a block of rows at a time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError


@dataclass
class CoefficientTable:
    """Coefficients of one group in importance order, ready for upload.

    ``index`` is the pywt index in array order ``(k_z, k_y, k_x)``; ``key_code`` is the
    band's :attr:`Band.code`.
    """

    level: np.ndarray       # (K,) int8
    key_code: np.ndarray    # (K,) uint8
    index: np.ndarray       # (K, 3) int32
    values: np.ndarray      # (K, C) float32
    importance: np.ndarray  # (K,) float32


#: rows :func:`ranked_rows` gives at a time: the band lookup's int64 work arrays (about 60 bytes a row) stay small
#: beside the tables made from them
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


def ranked_rows(group, order):
    """``(lo, hi, band_no, index)`` for each block of :data:`RANK_ROWS` rows of ``order`` (indices into the
    ascending positions of ``group``, a :class:`~clwave.model.wavelet.ChannelGroup`): the rows' band numbers and
    (k_z, k_y, k_x) indices (:meth:`~clwave.model.wavelet.ChannelGroup.locate`), the one home of the walk every
    ranked table is made by."""
    positions = group.all_positions()
    for lo in range(0, len(order), RANK_ROWS):
        hi = min(len(order), lo + RANK_ROWS)
        yield (lo, hi, *group.locate(positions[order[lo:hi]]))


def ranked_table(group, importance, order) -> CoefficientTable:
    """The kept coefficients ``order`` (indices into its ascending positions) of ``group`` (a
    :class:`~clwave.model.wavelet.ChannelGroup`) as a :class:`CoefficientTable` in that order; ``importance`` of each
    kept position."""
    n, channels = len(order), len(group.channels)
    levels = np.array([b.level for b in group.bands], dtype=np.int8)
    codes = np.array([b.code for b in group.bands], dtype=np.uint8)
    table = CoefficientTable(np.empty(n, np.int8), np.empty(n, np.uint8), np.empty((n, 3), np.int32),
                             np.empty((n, channels), np.float32),
                             np.take(importance, order).astype(np.float32, copy=False))
    for lo, hi, band_no, index in ranked_rows(group, order):
        table.index[lo:hi] = index
        table.level[lo:hi], table.key_code[lo:hi] = levels[band_no], codes[band_no]
        for ch in range(channels):
            table.values[lo:hi, ch] = np.take(group.values[ch], order[lo:hi])
    return table
