"""Refined bands of a perspective view (docs/splatting.md §8 "Refined bands"): a band whose image is large enough
that its footprints' interpolation (in slope between the nodes, in the texels) would take more than its share of
the accuracy target gets nodes ``r`` times closer and texels finer, in proportion to that image's predicted size,
so that nodes are spent only where the coefficients are large (sharp data's coarse levels).

A band's image is predicted from its coefficients before any footprint is made: its **size** is the largest sum
of ``|c|`` along a column of its lattice (the axis nearest the view), times its footprint's peak at the view's
axis, relative to the image maximum predicted from the approximation band (its signed column sums: the B-splines
sum to one across the lattice, so a column of coefficients ``c`` integrates to ``Σ c 2^{-m/2} d / |n_axis|``).
Its interpolation errors are that size times ``SLOPE_ERROR 4^{m - 3} (Δ / Δ_0)^2`` in slope (Δ the grid's step, Δ_0
the most :func:`~clwave.splat.perspective.slope_steps` allows) and ``TEXEL_ERROR (h / 2^m c)^2`` in texels (h the
texel, c the texel scale): bilinear reads err as the square of the step; the constants, and the slope errors'
growth as 4^m, are measured on Shepp–Logan, whose sharp edges set them, not derived (docs/splatting.md §8).
"""

from __future__ import annotations

import numpy as np

from ..model.geometry import support_extent
from .spectral import fft_texture

#: the error of a level-3 band's image relative to its predicted size (above) from the slope interpolation at the
#: step Δ_0, and of any band's from its texels per (texel / (2^m c))^2: measured (docs/splatting.md §8 "Refined bands")
SLOPE_ERROR = 2.2e-3
TEXEL_ERROR = 0.2
#: the share of the accuracy target (1e-2 of the image maximum, issue #33) that each level's bands may take with
#: their predicted interpolation errors before they are refined (the levels' errors peak at different pixels and
#: partly cancel: the whole image's came out 0.6 of their sum)
LEVEL_SHARE = 5e-3
MAX_REFINE = 4  # the most a band's slope step is divided by (its nodes grow as the square)
TEXEL_GAINS = (1.0, 2.0 ** 0.5, 2.0, 2.0 ** 1.5)  # the factors a band's texels may be made finer by


def column_sums(wv, group: int, axis: int) -> list:
    """Each band's coefficients summed along array ``axis`` (0 z, 1 y, 2 x): ``(|c| sums, signed sums)``, each the
    largest over the band's columns and channels; kept with the model (``wv.shared``), three axes at most."""
    def make():
        g = wv.groups[group]
        out = []
        for arr in g.dense_bands():
            out.append((float(np.abs(arr).sum(axis=axis).max(initial=0.0)),
                        float(np.max(arr.sum(axis=axis), initial=0.0))))
        return out
    return wv.shared(("cone column sums", group, axis), make)


def footprint_peaks(wav, bands, d_xyz, u, v) -> dict:
    """``{(level, key): peak}``: the largest magnitude of a unit coefficient's footprint along the view's axis
    (``u``, ``v`` its image axes), from the finest level of each key: a coarser one's is ``2^{-(m - m0)/2}`` as large
    (its footprints are the finest one's dilated, docs/splatting.md §8)."""
    out, finest = {}, {}
    for m, key in sorted(bands):
        finest.setdefault(key, m)
    for key, m0 in finest.items():
        h = 2.0 ** m0 * float(np.min(d_xyz)) / 4.0  # a quarter of the finest spacing: the peak to within 1e-3 or so
        extent = support_extent(wav, key, m0, d_xyz)
        nu, nv = (2 * int(np.ceil(float(np.abs(axis) @ extent) / (2.0 * h))) + 2 for axis in (u, v))
        peak = float(np.abs(fft_texture(wav, key, m0, d_xyz, u, v, nu, nv, nu * h, nv * h, 1)).max())
        for m, k in bands:
            if k == key:
                out[(m, key)] = peak * 2.0 ** (-(m - m0) / 2.0)
    return out


def level_errors(wv, group: int, view, texels, scale, steps, most) -> dict:
    """``{(level, approximation): (slope, texel)}``: the predicted interpolation errors (relative to the image
    maximum; the module's doc) of each level's bands among ``texels`` (band -> texel (h_u, h_v)) of ``wv``'s group
    ``group`` in ``view`` (perspective; texel scale ``scale``, :func:`~clwave.splat.perspective.texel_scale`), the
    approximation band apart; ``steps``: the slope grid's (u, v), ``most``: the largest that
    :func:`~clwave.splat.perspective.slope_steps` allows there (u, v).  Empty where no positive image is predicted."""
    g = wv.groups[group]
    d_xyz = np.array(wv.spacing[::-1], float)
    axis = int(np.argmax(np.abs(view.n)))  # the world axis nearest the view: columns along it (array axis 2 - it)
    sums = dict(zip([(b.level, b.key) for b in g.bands], column_sums(wv, group, 2 - axis)))
    coarsest = max(b.level for b in g.bands)
    top = sums[(coarsest, "aaa")][1] * 2.0 ** (-coarsest / 2.0) * d_xyz[axis] / abs(float(view.n[axis]))
    if not top > 0:
        return {}
    peaks = footprint_peaks(g.wavelet, texels, d_xyz, view.u, view.v)
    slope = SLOPE_ERROR * float(np.max(np.asarray(steps) / np.asarray(most))) ** 2 / 4.0 ** 3
    errors = {}
    for (m, key), h in texels.items():
        size = sums[(m, key)][0] * peaks[(m, key)] / top
        texel = TEXEL_ERROR * float(np.max(np.asarray(h) / np.asarray(scale))) ** 2 / 4.0 ** m
        parts = errors.setdefault((m, key == "aaa"), [0.0, 0.0])
        parts[0] += size * slope * 4.0 ** m
        parts[1] += size * texel
    return {level: tuple(parts) for level, parts in errors.items()}


def refined_bands(wv, group: int, view, texels, scale, steps, most) -> dict:
    """``{(level, key): (r, gain)}`` for the bands ``texels`` of :func:`level_errors`: each level's bands (the
    approximation band on its own) with their slope step divided by ``r`` and their texels by ``gain``, the least
    ``r^2 gain^2`` (the texels they cost) for which the level's predicted error fits :data:`LEVEL_SHARE`; ``(1, 1)``
    where it fits already, and for every band of other than cubic footprints (whose errors the constants are)."""
    plain = {band: (1, 1.0) for band in texels}
    if wv.groups[group].wavelet.order != 4:
        return plain
    options = sorted(((r, gain) for r in range(1, MAX_REFINE + 1) for gain in TEXEL_GAINS),
                     key=lambda o: (o[0] ** 2 * o[1] ** 2, o[0]))
    choice = {level: next((o for o in options if s / o[0] ** 2 + t / o[1] ** 2 <= LEVEL_SHARE), options[-1])
              for level, (s, t) in level_errors(wv, group, view, texels, scale, steps, most).items()}
    return {(m, key): choice.get((m, key == "aaa"), (1, 1.0)) for m, key in texels}
