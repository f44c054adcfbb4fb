"""The noise level of a volume, estimated from its wavelet transform (docs/model.md §2, noise).

Donoho & Johnstone (1994): in the finest diagonal band ('ddd' of level 1) a smooth signal leaves almost nothing and
white noise of deviation sigma leaves coefficients of deviation ``sigma * a``, ``a`` the band's analysis norm
(:meth:`~clwave.model.bspline.SplineWavelet.analysis_norm`, cubed: one per axis), so ``sigma = median(|d|) / 0.6745
/ a``, the median robust to the few large coefficients edges leave.  Two kinds of coefficients are left out, as
they have less noise: those whose filter reaches past the volume's faces (its zero extension; most of the band of a
small volume), and the zeros (an empty part of the volume, such as the outside of a field of view, has no noise to
measure).  A band that does not look like noise (edges or rounding rather than noise: fewer than
:data:`NOISE_LIKE` of its |d| within three deviations, against 99.7 % for Gaussian noise) gives no estimate.
"""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, InputError, NoisyModelWarning, warn_outside

#: the median of |x| for x standard normal (Phi^-1(3/4))
MAD_NORMAL = 0.6744897501960817
#: the least share of the band's |d| within three estimated deviations for the band to count as noise
NOISE_LIKE = 0.95
#: the largest noise gain (:func:`noise_gain`) at which ``noise=`` still removes most of the noise (docs/model.md §2)
GAIN_LIMIT = 4.0
#: a detail within this many times its band's noise is taken for noise: what ``noise=3``, the docs' advice, drops
NOISE_K = 3.0
#: "mostly": the share of a ``keep=``/``threshold=`` model's kept details within :data:`NOISE_K` noise levels, and of
#: the finest band's interior coefficients non-zero, past which it is a model of noise (:func:`warn_kept_noise`)
MOSTLY = 0.5
#: the histogram of |d|: the top 16 bits of a float32 (8 of exponent, 7 of mantissa: bins 0.8 % wide)
BIN_SHIFT = 16
#: an approximation coefficient is content beyond this many times its noise deviation (:func:`signal_box`): Gaussian
#: noise alone passes it once in 1.7 million coefficients, and with a neighbour that passes it too far less often
FRAME_K = 5.0
#: a model frames its content above the noise only where its values reach below 0 by at most this many times
#: FRAME_K noise deviations (:func:`signal_box`): content on a background of 0, as noise leaves it; values of both
#: signs (a CT in Hounsfield units, whose tissue at a crop's border would be taken for background) frame their box
FRAME_BELOW = 2.0
#: the fewest fine coefficients above the noise that :func:`signal_box` frames
FRAME_LEAST = 8
#: the least deviation (in units of the measured noise's) of the coefficients below the noise for :func:`signal_box`:
#: Gaussian noise gives 1 (less near the faces), a clean background 0
FRAME_NOISY = 0.5
#: the most coefficients of the approximation finer than the coarsest that :func:`signal_box` synthesizes
FRAME_CELLS = 128 ** 3


def finest_norm(wavelet) -> float:
    """The analysis norm of the finest diagonal band: the deviation of its coefficients for unit white noise."""
    return wavelet.analysis_norm("d", 1) ** 3


def interior(wavelet, shape) -> tuple:
    """The slices (z, y, x) of the finest band of a volume of ``shape`` whose coefficients read voxels alone: k reads
    the voxels 2k + 2 - L to 2k + 1 (L the filter's length, docs/chunked.md §2).  An axis too short to have
    any is taken whole."""
    lo, out = (wavelet.pywt.dec_len - 1) // 2, []
    for n in shape[:3]:
        out.append(slice(lo, n // 2) if n // 2 > lo else slice(None))
    return tuple(out)


def magnitudes(values) -> np.ndarray:
    """The non-zero |d| of some of the band's coefficients (float32)."""
    values = np.abs(np.asarray(values, np.float32))
    return values[values != 0]


def bins_of(magnitudes) -> np.ndarray:
    """The histogram bin of each magnitude (float32 >= 0: its bits order as its values)."""
    return np.ascontiguousarray(magnitudes, np.float32).view(np.uint32) >> BIN_SHIFT


def histogram(magnitudes) -> np.ndarray:
    """int64 (2^16,): the count of ``magnitudes`` in each bin."""
    return np.bincount(bins_of(magnitudes), minlength=1 << (32 - BIN_SHIFT)).astype(np.int64)


def median_rank(hist) -> tuple:
    """``(rank, bin, below)``: the rank of the lower median, ``(n - 1) // 2``, the bin that holds it, and the count
    of the bins before that one; the median is the value of rank ``rank - below`` in its bin (a chunked pass reads
    only those values)."""
    rank = (int(hist.sum()) - 1) // 2
    cumulative = np.cumsum(hist)
    b = int(np.searchsorted(cumulative, rank, side="right"))
    return rank, b, int(cumulative[b - 1]) if b else 0


def sigma_of(hist, median, wavelet):
    """The voxels' noise deviation from the histogram and lower median of the band's non-zero interior |d|; None
    where there are none, or they do not look like noise (fewer than :data:`NOISE_LIKE` within 3 deviations,
    counted by whole bins: a chunked pass finds the same)."""
    n = int(hist.sum())
    if n == 0:
        return None
    deviation = median / MAD_NORMAL
    within = hist[:int(bins_of(np.float32([3 * deviation]))[0]) + 1].sum()
    return deviation / finest_norm(wavelet) if within >= NOISE_LIKE * n else None


def measure_noise(wv):
    """Per channel of the model ``wv``, the noise deviation sigma of its voxels (stored units, None where its band
    does not look like noise) from its finest diagonal band; None where the model has no detail band (0 levels),
    holds only part of it (thresholded), or interpolates (its prefilter colours the noise)."""
    if wv.interpolate:
        return None
    sigmas = [None] * wv.channels
    for g in wv.groups:
        band, sl = g.bands[-1], g.band_slices()[-1]
        if wv.levels == 0 or sl.stop - sl.start != band.size:
            return None
        inside = (slice(None),) + interior(g.wavelet, wv.shape)
        for channel, values in zip(g.channels, g.values[:, sl].reshape((-1,) + band.shape)[inside]):
            mags = magnitudes(values)
            hist = histogram(mags)
            rank = median_rank(hist)[0]
            median = float(np.partition(mags, rank)[rank]) if len(mags) else 0.0
            sigmas[channel] = sigma_of(hist, median, g.wavelet)
    return tuple(sigmas)


def check_noise_known(sigmas, levels):
    """Refuse ``noise=`` where the model knows no noise level: ``sigmas`` None (0 levels, or a thresholded model that
    records none) or None for every channel (no noise measured); one line naming why and the fix."""
    if levels == 0:
        raise InputError("noise= needs a model of at least 1 level: the noise is measured in its finest detail band",
                         cli="--noise needs --levels 1 or more: the noise is measured in the finest detail band")
    if sigmas is None:
        raise InputError("noise= needs the model's finest band whole: threshold the model from_volume gave (or open a "
                         ".clw file that records its noise level)",
                         cli="--noise needs the volume, or a .clw file that records its noise level (info shows it)")
    if all(s is None for s in sigmas):
        said = (f"{{}} found no noise: the finest detail band does not look like noise (fewer than "
                f"{NOISE_LIKE:.0%} of its coefficients within 3 deviations; Gaussian noise has 99.7 %), as on a "
                f"clean or sharp volume; use {{}}")
        raise InputError(said.format("noise=", "keep= or threshold="),
                         cli=said.format("--noise", "--keep or --threshold"))


def band_noise(sigmas) -> np.ndarray:
    """The deviations ``noise=`` divides a group's channels by: 0 for a channel with no noise measured (its live
    details are all kept)."""
    return np.array([0.0 if s is None else s for s in sigmas])


def noise_gain(wavelet, band) -> float:
    """The deviation that white noise of deviation 1 gives a coefficient of ``band`` times the norm of its basis
    function: 1 in every band of an orthonormal wavelet (Haar); the B-spline wavelets' analysis filters amplify
    noise in their coarse bands (cubic: 24 at level 3), whose kept coefficients then bring that much noise back."""
    return float(np.prod([wavelet.analysis_norm(letter, band.level) * wavelet.norm(letter) for letter in band.key]))


def warn_noise_gain(groups, levels):
    """Warn that ``noise=`` removes little noise where a band's :func:`noise_gain` passes :data:`GAIN_LIMIT` (the
    approximation band, kept whole, holds that much of it): ``groups`` ``(wavelet, bands)`` of a model."""
    gains = {w.name: max(noise_gain(w, b) for b in bands) for w, bands in groups}
    name, gain = max(gains.items(), key=lambda item: item[1])
    if gain <= GAIN_LIMIT:
        return
    said = (f"{{}} on {name} wavelets at {levels} levels removes little noise: their coarse bands bring up to "
            f"{gain:.3g} times the voxels' noise into the model, the approximation band's kept whole; {{}} "
            f"(docs/model.md §2)")
    warn_outside(ClwaveWarning(said.format("noise=", "wavelet='linear' or 'haar' (or fewer levels) denoise"),
                               cli=said.format("--noise", "--wavelet linear or haar (or fewer --levels) denoise")))


def warn_kept_noise(wv, model, keep, threshold, importance_of):
    """Warn that ``model``, ``wv`` thresholded by ``keep=`` or ``threshold=`` (the one not None; neither: ``noise=``),
    keeps mostly noise: every channel's noise measured (:func:`measure_noise`), noise filling the finest band (more
    than :data:`MOSTLY` of its interior coefficients non-zero: white noise makes each non-zero, a clean
    piecewise-constant volume leaves them zero away from its edges, whose few large ones can look like noise), and
    more than :data:`MOSTLY` of the kept details within :data:`NOISE_K` times their band's noise (docs/model.md §2),
    their importance by ``importance_of`` (:func:`.wavelet.importance_of`, given: wavelet.py imports this module)."""
    if keep == 1 or threshold == 0 or (keep is None and threshold is None):  # the volume itself (zeros), or noise=
        return
    sigmas = wv.measure_noise()
    if not sigmas or None in sigmas or any(g.band_slices()[-1].stop - g.band_slices()[-1].start != g.bands[-1].size
                                           for g in wv.groups):  # a model read from a file: no whole finest band
        return
    filled = kept = noisy = 0
    for g, out in zip(wv.groups, model.groups):
        band, sl = g.bands[-1], g.band_slices()[-1]
        finest = g.values[:, sl].reshape((-1,) + band.shape)[(slice(None),) + interior(g.wavelet, wv.shape)]
        filled = max(filled, np.count_nonzero(finest) / max(finest.size, 1))
        imp = importance_of(out, None, model.frame, band_noise([sigmas[c] for c in g.channels]))
        detail = imp[out.band_slices()[0].stop:]
        kept, noisy = kept + detail.size, noisy + np.count_nonzero(detail <= NOISE_K)
    if filled <= MOSTLY or noisy <= MOSTLY * kept:
        return
    lo, hi = wv.value_range if wv.value_range is not None else (None, None)
    spread = ("" if lo is None or hi <= lo else
              f" ({100 * max(sigmas) / (hi - lo):.2g} % of its value range {lo:.3g} to {hi:.3g})")
    amplify = ("" if max(noise_gain(g.wavelet, b) for g in wv.groups for b in g.bands) <= GAIN_LIMIT else
               ", whose coarse bands amplify noise: the model can be farther from the noise-free volume than the input")
    said = (f"this volume looks noisy: its voxels' noise deviation is {', '.join(f'{s:.3g}' for s in sigmas)}{spread}, "
            f"measured in the finest band, and {100 * noisy / kept:.0f} % of the details {{}} keeps are within "
            f"{NOISE_K:g} times their band's noise: most of the model's detail is noise "
            f"({'/'.join(dict.fromkeys(g.wavelet.name for g in wv.groups))} wavelets{amplify}); to denoise, {{}} "
            f"(docs/model.md §2)")
    rule = f"keep={keep:g}" if threshold is None else f"threshold={threshold:g}"
    linear = all(g.wavelet.name == "linear" for g in wv.groups)  # the advice then only the threshold
    api, cli = ("threshold(noise=3)", "--noise 3") if linear else \
        ("wavelet='linear' and threshold(noise=3)", "--wavelet linear --noise 3")
    warn_outside(NoisyModelWarning(said.format(rule, "use " + api),
                                   cli=said.format("--" + rule.replace("=", " "), "use " + cli)))


def signal_box(wv):
    """World (x, y, z) corners ``(lo, hi)`` of the content of a noisy model, what a camera frames (docs/coordinates.md
    §2), as every voxel of a noisy volume is non-zero; 0 is the background, as for :meth:`Volume.content_box`.  Its
    content: the coefficients of an approximation of the content's sign (per channel) above :data:`FRAME_K` times
    their noise deviation (:meth:`~clwave.WaveletVolume.measure_noise` times the level's analysis norm) that have such
    a neighbour (a lone one is noise); found at the coarsest level, whose noise is whole (the approximation band is
    kept whole), then at the finest level of at most :data:`FRAME_CELLS` coefficients, as the clusters there that
    reach a coarse cell found (where a threshold kept part of the details, their largest noise makes clusters of its
    own): the box of their cells.  None where no channel's noise is known, the values reach below 0 by more than
    :data:`FRAME_BELOW` times :data:`FRAME_K` deviations (not content on a background of 0), the coarsest coefficients
    below it vary less than :data:`FRAME_NOISY` times it (no noise there: a clean volume, whose few edges looked like
    noise), or fewer than :data:`FRAME_LEAST` pass."""
    sigmas = wv.measure_noise() or ()
    if not any(sigmas) or wv.value_range is not None and \
            wv.value_range[0] < -FRAME_BELOW * FRAME_K * max(s or 0.0 for s in sigmas):
        return None
    half = np.array(wv.shape[:3]) * np.array(wv.spacing) / 2  # (z, y, x)
    coarse, signs = [], []  # per group: (the coarse coefficients found, their centres), the content's signs
    for g in wv.groups:
        ratio, axes = _ratios(wv, g, wv.levels, sigmas)
        inside = ratio[np.ix_(*(np.abs(a - o) < h for a, o, h in zip(axes, wv.origin[::-1], half)))].reshape(
            -1, ratio.shape[3])
        rest = inside[(np.abs(inside) <= 1).all(axis=1)]  # (n, C): the background's, in FRAME_K deviations
        spread = np.median(np.abs(rest - np.median(rest, axis=0)), axis=0) / MAD_NORMAL * FRAME_K if len(rest) else 0
        if np.max(spread, initial=0.0) < FRAME_NOISY:
            return None
        # the content's sign per channel: the filters' ringing, of the other sign about it, weighs nothing
        signs.append(np.sign(np.sum(ratio * (np.abs(ratio) > 1), axis=(0, 1, 2))))
        coarse.append((_clustered(ratio, signs[-1]), axes))
    box = _union([_cells_box(found, axes, wv.levels, wv.spacing) for found, axes in coarse])
    fine = next((level for level in range(1, wv.levels) if np.prod(wv.shape[:3]) >> 3 * level <= FRAME_CELLS), None)
    if box is not None and fine is not None:  # the clusters at the finer level that reach a coarse cell found
        boxes = []
        for g, sign, seeds in zip(wv.groups, signs, coarse):
            ratio, axes = _ratios(wv, g, fine, sigmas)
            boxes.append(_cells_box(_grown(_clustered(ratio, sign), axes, *seeds, wv.levels, wv.spacing), axes, fine,
                                    wv.spacing))
        box = _union(boxes)
    return box[:2] if box is not None and box[2] >= FRAME_LEAST else None


def _ratios(wv, group, level, sigmas) -> tuple:
    """The group's approximation at ``level`` over :data:`FRAME_K` times its noise deviation, float32 (Z, Y, X, C),
    and the world coordinates of its coefficients' centres along z, y and x (three 1-D arrays)."""
    from .geometry import fine_to_world, support_centres
    from .transform import synthesize

    bands = [(number, b) for number, b in enumerate(group.bands) if b.level > level or b.key == "aaa"]
    dense = []
    for number, b in bands:
        flat, sl = np.zeros((b.size, len(group.channels)), np.float32), group.band_slices()[number]
        flat[np.arange(b.size) if group.positions is None else group.positions[sl] - b.start] = group.values[:, sl].T
        dense.append(flat.reshape(*b.shape, -1))
    approx, start = synthesize(group.wavelet, [b for _, b in bands], dense)
    limit = [FRAME_K * (sigmas[c] or np.inf) * group.wavelet.analysis_norm("a", level) ** 3 for c in group.channels]
    ratio = approx.astype(np.float32, copy=False) / np.float32(limit)
    index = np.arange(max(ratio.shape[:3]))[:, None] + np.array(start)  # (n, 3): the index along each axis
    world = fine_to_world(support_centres(group.wavelet, "aaa", level, index), group.wavelet.order, *wv.frame)
    return ratio, [world[:n, 2 - axis] for axis, n in enumerate(ratio.shape[:3])]


#: the 26 neighbours of a coefficient
NEIGHBOURS = np.ones((3, 3, 3), bool)
NEIGHBOURS[1, 1, 1] = False


def _clustered(ratio, sign) -> np.ndarray:
    """(Z, Y, X) bool: the coefficients of ``ratio`` (:func:`_ratios`) above the noise in a channel with the content's
    ``sign`` that have such a neighbour."""
    from scipy.ndimage import binary_dilation

    above = (ratio * sign).max(axis=3) > 1
    return above & binary_dilation(above, NEIGHBOURS)


def _grown(found, axes, seeds, seed_axes, seed_level, spacing) -> np.ndarray:
    """The clusters (26-connected) of the fine coefficients ``found`` centred at ``axes`` that reach a coarse cell
    (``2^seed_level`` voxels a side) of the coefficients ``seeds`` centred at ``seed_axes`` (:func:`_ratios`)."""
    from scipy.ndimage import label

    cell = [np.round((a - s[0]) / (2.0 ** seed_level * d)).astype(int) for a, s, d in zip(axes, seed_axes, spacing)]
    inside = np.ix_(*((c >= 0) & (c < n) for c, n in zip(cell, seeds.shape)))
    seeded = np.zeros(found.shape, bool)
    seeded[inside] = seeds[np.ix_(*(c[(c >= 0) & (c < n)] for c, n in zip(cell, seeds.shape)))]
    labels = label(found, np.ones((3, 3, 3)))[0]
    return np.isin(labels, np.unique(labels[found & seeded]))


def _cells_box(found, axes, level, spacing):
    """``(lo, hi, count)``: the world (x, y, z) box of the cells (``2^level`` voxels a side) of the coefficients
    ``found`` (:func:`_clustered`) centred at ``axes`` (:func:`_ratios`), and their count; None where none is."""
    if not found.any():
        return None
    half = 2.0 ** level * np.array(spacing) / 2
    ends = [a[found.any(axis=tuple(o for o in range(3) if o != axis))] for axis, a in enumerate(axes)]
    lo = np.array([e.min() for e in ends]) - half
    hi = np.array([e.max() for e in ends]) + half
    return lo[::-1], hi[::-1], int(found.sum())


def _union(boxes):
    """The box of the groups' :func:`_cells_box` es (None where none found any), their counts added."""
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        return None
    return (np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0), sum(b[2] for b in boxes))
