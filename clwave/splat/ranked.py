"""What a :class:`~clwave.splat.renderer.SplatRenderer` holds of each channel group on the host: its coefficients in
importance order, the bands present with each one's first coefficient, and the cumulative energy the viewer's
error figures come from (docs/splatting.md, docs/viewer.md §2)."""

from __future__ import annotations

import numpy as np

from ..model.wavelet import WaveletVolume


def ranked_groups(wv: WaveletVolume, tables=None) -> list:
    """Per group of ``wv``, what a renderer holds: its coefficients ranked (``tables``, else
    :meth:`WaveletVolume.ranked`), their count and channels, the present bands, each with its first coefficient in
    that order (a prefix needs only the bands it reaches; at 1 % kept 8 of hydrogen's 22 have none), and the
    cumulative energy."""
    groups = []
    for gi, g in enumerate(wv.groups):
        table = wv.ranked(gi) if tables is None else tables[gi]
        ids = table.level.astype(np.uint8) * np.uint8(8) + table.key_code  # band ids, < 64 (tables.MAX_LEVELS)
        counts = np.bincount(ids, minlength=64)
        present = {(b.level, b.key): int(np.argmax(ids == b.level * 8 + b.code)) for b in g.bands
                   if counts[b.level * 8 + b.code]}
        groups.append(dict(table=table, count=len(table.level), channels=len(g.channels), present=present,
                           energy=_energy_prefix(table.values)))
    return groups


def _energy_prefix(values) -> np.ndarray:
    """Cumulative coefficient energy sum c^2 over channels, in importance order (a channel at a time: no float64
    copy of the (K, C) values)."""
    energy = np.zeros(len(values))
    for channel in np.asarray(values).T:
        energy += np.square(channel, dtype=np.float64)
    return np.cumsum(energy, out=energy)
