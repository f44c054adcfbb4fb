"""What a :class:`~clwave.splat.renderer.SplatRenderer` holds of each channel group: its coefficients in importance
order as the kernels read them, made a block of rows at a time and held once (on a device that shares the host's
memory the device arrays are these), the bands present with each one's first coefficient, and the cumulative energy
the viewer's error figures come from (docs/splatting.md §6, docs/viewer.md §2)."""

from __future__ import annotations

from functools import partial

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..model import ranking
from ..model.ranking import RankedTable, by_importance, ranked_table
from ..model.wavelet import WaveletVolume


def ranked_groups(wv: WaveletVolume, orders=None) -> list:
    """Per group of ``wv``, what a renderer holds: its coefficients ranked (``orders``: per group, indices into its
    ascending positions, e.g. :func:`~clwave.view.prefix.prefix_first`'s; else by importance,
    :func:`~clwave.model.ranking.by_importance`) as a :class:`~clwave.model.ranking.RankedTable`, their count and
    channels, the present bands, each with its first coefficient in that order (a prefix needs only the bands it
    reaches; at 1 % kept 8 of hydrogen's 22 have none), and the cumulative energy (:class:`CumulativeEnergy`)."""
    groups = []
    for gi, g in enumerate(wv.groups):
        order = by_importance(wv.importance(g)) if orders is None else orders[gi]
        first = np.full(len(g.bands), -1)  # each band's first row (-1: none yet)
        table = ranked_table(g, order, each_block=partial(_first_rows, first))
        present = {(b.level, b.key): int(f) for b, f in zip(g.bands, first) if f >= 0}
        groups.append(dict(table=table, count=len(order), channels=table.channels, present=present,
                           energy=CumulativeEnergy(table)))
    return groups


def _first_rows(first, lo, band_no):
    """Note in ``first`` (per band, -1: not seen) the first row of each band not seen before the rows from ``lo``,
    whose band numbers are ``band_no``."""
    for b in np.flatnonzero((first < 0) & (np.bincount(band_no, minlength=len(first)) > 0)):
        first[b] = lo + np.argmax(band_no == b)


#: coefficients between two sums a :class:`CumulativeEnergy` holds (a divisor of ranking.RANK_ROWS, the blocks it
#: is made in)
ENERGY_STEP = 1024


class CumulativeEnergy:
    """The cumulative coefficient energy of a :class:`RankedTable`: ``energy[i]`` is the sum of c^2 over the channels
    of its first i + 1 coefficients, in float64, bit for bit ``np.cumsum`` of each coefficient's sum (a channel at a
    time).  It holds that sum at every :data:`ENERGY_STEP`-th coefficient only, and adds the few after it from the
    table when asked: 8 bytes a coefficient less (0.4 GiB at 1024^3, 5 %: docs/viewer.md §2)."""

    def __init__(self, table: RankedTable):
        self.table = table
        self.marks = np.zeros(len(table.coef) // ENERGY_STEP)  # the sum to coefficient (k + 1) ENERGY_STEP - 1
        n = len(self)
        for lo in range(0, n, ranking.RANK_ROWS):  # no float64 sum of every coefficient at once
            self._mark(lo, min(n, lo + ranking.RANK_ROWS))

    def _sums(self, lo, hi, start) -> np.ndarray:
        """The cumulative sums of coefficients lo .. hi, from ``start``, the sum before lo (np.cumsum is sequential:
        the same bits as one cumsum of them all)."""
        energy = np.zeros(hi - lo)
        for channel in self.table.values[lo:hi].T:
            energy += np.square(channel, dtype=np.float64)
        energy[:1] += start
        return np.cumsum(energy, out=energy)

    def _mark(self, lo, hi):
        """Take the sums of coefficients lo .. hi (lo a multiple of ENERGY_STEP; each block after the one before)."""
        assert lo % ENERGY_STEP == 0 and (hi % ENERGY_STEP == 0 or hi == len(self)), (lo, hi)
        sums = self._sums(lo, hi, self.marks[lo // ENERGY_STEP - 1] if lo else 0.0)
        self.marks[lo // ENERGY_STEP: hi // ENERGY_STEP] = sums[ENERGY_STEP - 1::ENERGY_STEP]

    def __len__(self) -> int:
        return len(self.table.coef)

    def __getitem__(self, i) -> float:
        n = len(self)
        i = int(i) + n if i < 0 else int(i)
        if not 0 <= i < n:
            raise IndexError(f"coefficient {i} of {n}")
        k = (i + 1) // ENERGY_STEP  # marks before it
        start = self.marks[k - 1] if k else 0.0
        lo = k * ENERGY_STEP
        return float(start) if lo == i + 1 else float(self._sums(lo, i + 1, start)[-1])

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = self._sums(0, len(self), 0.0)
        return out if dtype is None else out.astype(dtype)


def on_device(cc, table: RankedTable) -> tuple:
    """``(coef, values)``, the device arrays of ``table``: on a device that shares the host's memory (PoCL on the
    CPU) the host's arrays themselves (``USE_HOST_PTR``: no copy), elsewhere a copy (docs/splatting.md §6)."""
    q = cc.queue
    if not len(table.coef) or not _shares_host_memory(cc.device):
        return cla.to_device(q, table.coef), cla.to_device(q, table.packed)
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR
    return tuple(cla.Array(q, a.shape, a.dtype, data=cl.Buffer(cc.ctx, flags, hostbuf=a))
                 for a in (table.coef, table.packed))


def _shares_host_memory(device) -> bool:
    try:
        return bool(device.host_unified_memory)
    except cl.Error:  # deprecated since OpenCL 2.0: a platform may not answer
        return False
