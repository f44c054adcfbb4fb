"""Coefficients in importance order (the paper's §5.2 ranking): the order :meth:`WaveletVolume.ranked
<clwave.model.wavelet.WaveletVolume.ranked>` gives and the tables the splat renderer uploads in it."""

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


#: rows :func:`ranked_table` makes at a time
RANK_ROWS = 1 << 22


def by_importance(importance) -> np.ndarray:
    """Indices of ``importance`` (float32 >= 0, a group's in its ascending position order) by decreasing
    importance, ties by position: the importance order of :meth:`WaveletVolume.ranked`.  One sort of 64-bit keys,
    the importance's bits inverted (a float >= 0 orders as its bits) over the index: NumPy sorts those with its
    vector sort, 6 times faster than a stable argsort of the importance (docs/viewer.md §2)."""
    n = len(importance)
    if n >= 1 << 32:
        raise InputError(f"a group of {n:,} coefficients is more than ranking takes (2^32)")
    keys = (~np.asarray(importance, np.float32).view(np.uint32)).astype(np.uint64) << np.uint64(32)
    keys |= np.arange(n, dtype=np.uint64)
    keys.sort()
    return (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)


def ranked_table(group, importance, order) -> CoefficientTable:
    """The kept coefficients ``order`` (indices into its ascending positions) of ``group`` (a
    :class:`~clwave.model.wavelet.ChannelGroup`) as a :class:`CoefficientTable` in that order; ``importance`` of each
    kept position.  Made :data:`RANK_ROWS` rows at a time, so that the band lookup's int64 work arrays stay small
    beside the table."""
    n, channels = len(order), len(group.channels)
    levels = np.array([b.level for b in group.bands], dtype=np.int8)
    codes = np.array([b.code for b in group.bands], dtype=np.uint8)
    table = CoefficientTable(np.empty(n, np.int8), np.empty(n, np.uint8), np.empty((n, 3), np.int32),
                             np.empty((n, channels), np.float32),
                             np.take(importance, order).astype(np.float32, copy=False))
    positions = group.all_positions()
    for lo in range(0, n, RANK_ROWS):
        part = order[lo:lo + RANK_ROWS]
        band_no, table.index[lo:lo + len(part)] = group.locate(positions[part])
        table.level[lo:lo + len(part)], table.key_code[lo:lo + len(part)] = levels[band_no], codes[band_no]
        for ch in range(channels):
            table.values[lo:lo + len(part), ch] = np.take(group.values[ch], part)
    return table
