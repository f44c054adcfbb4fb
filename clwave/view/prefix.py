"""A ``.clw`` file opened by its prefix first (docs/viewer.md §2): the viewer serves at once from the file's most
important coefficients and reads the rest in the background.

The file stores its coefficients by importance tier, the coarsest approximation first (docs/chunked.md §4), so the
``PREFIX`` most important of them (the approximation first) are a prefix of its reading
(``WaveletVolume.open(path, keep=)``, the model ``open(path).threshold(keep=)``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.clw import read_header
from ..model.wavelet import WaveletVolume, check_thresholding

#: coefficients (per channel group) the viewer serves from at once: at 1024^3 (5 % kept) about 2 % of the file,
#: read in about a second, and enough for the display window (frames.WINDOW_COEFFICIENTS)
PREFIX = 1 << 20


class PrefixFirst:
    """A ``.clw`` file's ``keep`` most important coefficients (None: all it holds), of which :attr:`prefix` (the
    first :data:`PREFIX`) is read on construction and :meth:`whole` reads them all.  :attr:`complete`: the prefix
    is all of them already."""

    def __init__(self, path, keep=None):
        self.path, self.keep = Path(path), None if keep is None else check_thresholding(keep, None, None)[0]
        n = int(np.prod(read_header(path)["shape"]))  # the voxels, from the header alone
        share = min(1.0, PREFIX / n)
        self.prefix = WaveletVolume.open(path, keep=share if self.keep is None else min(self.keep, share))
        budget = max(1, round(share * n))
        # every tier was read where a group holds fewer than the budget
        self.complete = (self.keep is not None and self.keep <= share) or share == 1.0 or all(
            g.kept < budget for g in self.prefix.groups)

    def whole(self) -> WaveletVolume:
        """The whole model (the file, or its ``keep`` most important coefficients)."""
        return WaveletVolume.open(self.path, keep=self.keep)
