"""A ``.clw`` file opened by its prefix first (docs/viewer.md §2): the viewer serves at once from the file's most
important coefficients and reads the rest in the background.

The file stores its coefficients by importance tier, the coarsest approximation first (docs/chunked.md §4), so the
``PREFIX`` most important of them (the approximation first) are a prefix of its reading
(``WaveletVolume.open(path, keep=)``, the model ``open(path).threshold(keep=)``).  The whole model, once read, is
ranked with the prefix's coefficients first (:func:`prefix_first`), so that the prefix's renderer extends to it.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from ..errors import ClwaveError, FileFormatError, caught_warnings
from ..io.clw import read_header
from ..model.budget import check_thresholding, kept_count, warn_stored
from ..model.ranking import by_importance
from ..model.wavelet import WaveletVolume
from ..raytrace.staged import read_coarse
from ..threads import Abandoned

#: coefficients (per channel group) the viewer serves from at once: at 1024^3 (5 % kept) about 2 % of the file
#: (its reading time: docs/viewer.md §2), and enough for the display window (frames.WINDOW_COEFFICIENTS)
PREFIX = 1 << 20


class PrefixFirst:
    """A ``.clw`` file's ``keep`` most important coefficients (None: all it holds), of which :attr:`prefix` (the
    first :data:`PREFIX`) is read on construction and :meth:`whole` reads them all.  :attr:`complete`: the prefix
    is all of them already; :attr:`model_error`: the header's, of the whole file's model (docs/chunked.md §4)."""

    def __init__(self, path, keep=None):
        self.path, self.keep = Path(path), None if keep is None else check_thresholding(keep, None, None)[0]
        header = read_header(path)
        n = int(np.prod(header["shape"]))  # the voxels, from the header alone
        self.model_error = header.get("model_error")  # the whole file's, against its input (None: not recorded)
        share = min(1.0, PREFIX / n)
        # what the file stores is told of `keep`, not of the prefix's share (this thread's: a notebook's other viewers
        # render meanwhile)
        with caught_warnings():
            self.prefix = WaveletVolume.open(path, keep=share if self.keep is None else min(self.keep, share))
        budget = kept_count(share, n)  # the prefix's coefficients a group, as the file is read (None: all of them)
        # every tier was read where a group holds fewer than the budget
        self.complete = budget is None or (self.keep is not None and self.keep <= share) or all(
            g.kept < budget for g in self.prefix.groups)
        if self.complete:  # else told when the whole is read (WaveletVolume.open)
            warn_stored(self.prefix, self.keep, path)
        self._coarse, self._taken, self._holding = None, False, threading.Lock()

    def coarse(self) -> tuple:
        """What a staged tracer's coarse stage reads of the file (:func:`~clwave.raytrace.staged.read_coarse`): the
        reading :meth:`whole` holds (let go here), else read now (under the lock: :meth:`whole` starts the rest's
        reading after it); checked to be of the prefix's file (:func:`check_frame`: a file replaced meanwhile)."""
        with self._holding:
            held, self._coarse, self._taken = self._coarse, None, True
            reading = read_coarse(self.path) if held is None else held
        check_frame(reading[0], self.prefix)
        return reading

    def whole(self, coarse_first=False, stop=None) -> WaveletVolume:
        """The whole model (the file, or its ``keep`` most important coefficients).  ``coarse_first``: the coarse
        stage's reading (:meth:`coarse`, where not taken yet) is read before it and held until taken or the whole is
        read: h5py serialises its calls, so a coarse stage asked for meanwhile would wait behind the whole's reads
        (their times: docs/viewer.md §2); that reading failing, nothing is held, and :meth:`coarse` reads
        again (and fails for the shaded views alone).  ``stop`` (a ``threading.Event``): set once the coarse reading
        is done, the whole is not read (:class:`~clwave.threads.Abandoned`)."""
        with self._holding:
            if coarse_first and not self._taken:
                try:
                    self._coarse = read_coarse(self.path)
                except ClwaveError:  # the coarse stage's parts of the file only (its summaries, docs/chunked.md)
                    pass
        if stop is not None and stop.is_set():
            raise Abandoned(f"the reading of {self.path.name} was given up")
        try:
            return WaveletVolume.open(self.path, keep=self.keep)
        finally:
            with self._holding:
                self._coarse = None  # not taken: a coarse stage made later reads the file alone


def part_rows(whole: WaveletVolume, prefix: WaveletVolume) -> list:
    """Per group, the rows of ``whole``'s ascending positions that hold ``prefix``'s coefficients; a prefix that is
    not a part of ``whole`` (the file replaced meanwhile) is a FileFormatError."""
    check_frame(whole, prefix)
    out = []
    for g, part in zip(whole.groups, prefix.groups, strict=True):
        positions, kept = g.all_positions(), part.all_positions()
        rows = np.searchsorted(positions, kept)
        if not (np.all(rows < len(positions)) and np.array_equal(positions[rows], kept)
                and np.array_equal(g.values[:, rows], part.values)):
            raise _replaced()
        out.append(rows)
    return out


def check_frame(read: WaveletVolume, prefix: WaveletVolume):
    """A FileFormatError where ``read`` (a model read from the prefix's file after it: the whole, or the coarse
    stage's approximation) has another frame, levels or channel groups than ``prefix`` (the file replaced meanwhile:
    no page shows two volumes)."""
    def frame(wv):  # what a replaced file may change besides the coefficients
        return wv.shape, wv.spacing, wv.origin, wv.levels, [(g.wavelet.name, g.channels) for g in wv.groups]

    if frame(read) != frame(prefix):
        raise _replaced()


def _replaced() -> FileFormatError:
    return FileFormatError("the file's prefix is not a part of the whole file read after it (was the file replaced "
                           "meanwhile?); open it again")


def prefix_first(whole: WaveletVolume, prefix: WaveletVolume, rows=None) -> list:
    """Per group, the order of the coefficients of ``whole`` (indices into its ascending positions, for
    :func:`~clwave.splat.ranked.ranked_groups`): those of ``prefix`` (a part of it, ``threshold(keep=)``; checked by
    :func:`part_rows`, or its ``rows`` where the caller has them) by importance, then the rest by importance (one sort,
    :func:`~clwave.model.ranking.by_importance`).  Its first rows are ``prefix.ranked()``'s, so that the prefix's
    renderer extends to it (``SplatRenderer.extend``).  It is not ``whole.ranked()``'s: a prefix holds the
    approximation first (docs/model.md §2), and in importance order some of it comes after the rest's most
    important, so an image of every coefficient is the same sum in another order (docs/viewer.md §2)."""
    orders = []
    for g, part, kept in zip(whole.groups, prefix.groups, part_rows(whole, prefix) if rows is None else rows):
        importance = whole.importance(g)
        importance[kept] = prefix.importance(part)  # as the prefix's renderer ranked them (without a file's focus)
        orders.append(by_importance(importance, first=kept))
    return orders
