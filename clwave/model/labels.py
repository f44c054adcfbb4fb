"""Label maps (segmentations: an integer per voxel naming a region): what tells one, and the warning that a wavelet
of order above 1 blurs it (docs/model.md §5).  B-splines of order 2 and up interpolate between the labels on either
side of every boundary, so a boundary between labels 1 and 5 passes through 2, 3 and 4, which a transfer function
then shows; Haar's (order 1) model is piecewise constant on the voxels, every label exact."""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, warn_outside

#: Up to DENSE_LABELS distinct values (labels, the background included) numbered densely: the largest label under
#: DENSE times their count (0 .. 40 of 30 labels is; 0, 26, 51, .. 255, a piecewise-constant phantom's 8-bit
#: intensities, 6 values, is not); more, up to MAX_LABELS, numbered sparsely, as an atlas's table numbers them: their
#: count at most SPARSE times the largest (FreeSurfer's aparc+aseg, some 110 labels in 0 .. 2035, is; the hundreds of
#: intensities of an 8-bit MRI, filling 0 .. 255, are not; nor, in even steps, are they scaled by 4).  Labels below
#: 2^24 (float32's integers).
DENSE_LABELS, MAX_LABELS, DENSE, SPARSE = 64, 256, 16, 0.25
#: Regions, not noise: at least this share of the voxel pairs along x outside the background hold one value; and
#: boundaries, not a smooth intensity quantised coarsely: at least JUMPS of the pairs that differ jump by more than 1
#: (0.47 for nested shells numbered outwards 1 .. 4 in 0; 0.01 for hydrogen's density quantised to 0 .. 10).
SAME_NEIGHBOURS, JUMPS = 0.75, 0.25
#: 3 to FEW_LABELS values numbered densely, forming regions, are labels whatever their jumps: nested regions
#: thresholded from a smooth field (a tumour's core in its oedema; trial27's 0 .. 5, 0.004 % of its steps jump) step
#: by 1 as a smooth image quantised coarsely does, and an image of 8 levels or fewer (3 bits) is a rarity (hydrogen's
#: density quantised to 0 .. 10 is not taken); a 0/1 mask (2 values) is no label map.
FEW_LABELS = 8
#: More than DENSE_LABELS numbered densely (a parcellation of hundreds, a cell mask of thousands), as an 8-bit image's
#: values are: boundaries between regions, not edges blurred through the values between nor noise: at least ABRUPT of
#: the pairs along x that differ jump by more than 1 between two pairs that do not (a a | b b); 0.68 to 1 for the
#: label maps of tests/test_labels.py's corpus, at most 0.02 for its images (0.09: an 8-bit T1 with plateaus).
ABRUPT = 0.5
#: The distinct values are counted on an even sample of at most this many voxels.
SAMPLE = 1 << 20


def looks_like_labels(data) -> bool:
    """Whether ``data`` (an in-memory array as stored, before float32) looks like a label map: integers (or booleans),
    none negative, 2 to :data:`DENSE_LABELS` distinct values numbered densely (:data:`DENSE`) or up to
    :data:`MAX_LABELS` numbered sparsely (:data:`SPARSE`), not in even steps, forming regions with boundaries
    (:data:`SAME_NEIGHBOURS`, :data:`JUMPS`; :data:`FEW_LABELS` need no jumps); or more numbered densely, their
    boundaries abrupt (:data:`ABRUPT`).  A CT in HU (negative, thousands of values) or an MRI (hundreds of values, noise
    between neighbours, edges blurred) is not; a float volume is never looked at.  Cost: a min and a max over an integer
    volume, then only where they pass a sort of :data:`SAMPLE` voxels and, where its values pass, one pass over the
    neighbours in evenly spaced z planes of at most 4 × :data:`SAMPLE` voxels (copies in the least signed type that
    holds their differences)."""
    if getattr(data, "dtype", None) is None or data.dtype.kind not in "biu" or data.ndim != 3 or not data.size:
        return False
    top = int(data.max())
    if int(data.min()) < 0 or top >= 1 << 24:
        return False
    values = np.unique(data.flat[::max(1, data.size // SAMPLE)]).astype(np.int64)  # flat: no copy if strided
    count = len(values)
    dense = count >= 2 and top < DENSE * count
    sparse = DENSE_LABELS < count <= MAX_LABELS and count <= SPARSE * top and np.gcd.reduce(np.diff(values)) == 1
    if not (dense or sparse):
        return False
    many = dense and count > DENSE_LABELS
    planes = data[::max(1, data.size // (4 * SAMPLE))].astype(np.min_scalar_type(-top - 1))  # a bounded cost
    right, left = planes[..., 1:], planes[..., :-1]  # neighbours along x
    step = np.abs(right - left)
    differ, jumps = step != 0, step > 1
    if not many or sparse:
        content = (right != 0) | (left != 0)
        pairs, differing = int(np.count_nonzero(content)), int(np.count_nonzero(differ))
        if pairs > 0 and pairs - differing >= SAME_NEIGHBOURS * pairs and \
                (3 <= count <= FEW_LABELS or np.count_nonzero(jumps) >= JUMPS * differing):
            return True
        if not many:
            return False
    abrupt = jumps[..., 1:-1] & ~differ[..., :-2] & ~differ[..., 2:]  # of the pairs with a pair on either side
    return bool(np.count_nonzero(abrupt) >= ABRUPT * max(1, np.count_nonzero(differ[..., 1:-1])))


def warn_blurred_labels(volume, wavelet):
    """A :class:`ClwaveWarning` where ``volume`` is a label map or its classification (:attr:`Volume.labels`) given
    a ``wavelet`` of order above 1 (any channel's), naming Haar and the categorical transfer function that show its
    labels exactly."""
    from .bspline import wavelet_for

    if not volume.labels:
        return
    wav = max((wavelet_for(w) for w in (wavelet if isinstance(wavelet, (list, tuple)) else [wavelet])),
              key=lambda w: w.order)
    if wav.order == 1:
        return
    blurs = ("interpolates between labels, so every boundary passes through the labels numbered between its two"
             if volume.channels == 1 else "blurs and rings its colours across every boundary (its classification)")
    line = (f"the volume looks like a label map (a segmentation); a {wav.name} wavelet (order {wav.order}) {blurs}: "
            f"give it {{}} and a categorical transfer function {{}} (docs/model.md §5)")
    warn_outside(ClwaveWarning(line.format("wavelet='haar'", "(TransferFunction.labels)"),
                               cli=line.format("--wavelet haar", "(--tf FILE.json or .csv)")))
