"""Refined bands of a perspective view (docs/splatting.md §8 "Refined bands"): levels whose footprints' interpolation
errors (in slope between the nodes, in the texels) would take the view past the accuracy target get nodes ``r``
times closer and texels finer, so that nodes are spent where the errors are.

The errors are predicted as images across the view from the coefficients and the footprints at the view, before any
texture is made, with no constant fitted to data.  Each band's coefficients are summed along the view onto one grid
across it (:func:`projections`: ``P_b``, and ``Q_b`` of their squares), and its footprint made there at five slopes
about the slope grid's node farthest from the view's axis (:func:`error_kernels`).  A pixel reads every splat at its
own slope, at one place in one slope cell, where a bilinear read of quasi-interpolants
(:func:`~clwave.splat.perspective.quasi_interpolant`) errs by between -1/16 and +1/16 of the footprint's second
difference over a slope step along each axis, ``D_u`` and ``D_v``: so slope errors add with the coefficients' signs,
``Σ_b P_b ⊛ (±D_u ± D_v) / 16``.  A splat's texels sit at a phase ``x`` of its own (its depth magnifies it), where
the read errs by ``(x (1 - x) / 2 - 1/16) h^2 G''`` an axis: a mean ``h^2 G'' / 48`` that adds with the signs and a
variance ``h^4 G''^2 / 720`` that adds in squares over the splats (:func:`level_errors`).  All relative to the image
maximum predicted the same way from the approximation band, ``max P_aaa ⊛ G_aaa``; the levels are summed as their
reads add (:func:`predicted_error`) and refined greedily per texel (:func:`refined_bands`).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from ..model.geometry import fine_to_world, support_centres, support_extent
from .spectral import fft_texture

#: the largest predicted interpolation error (:func:`predicted_error`, relative to the image maximum) a view may have
#: before a level is refined: issue #33's whole target, as the prediction is above the measured error (0.57-0.75 of
#: it unrefined on sharp data, docs/splatting.md §8 "Refined bands")
SHARE = 1e-2
MAX_REFINE = 4  # the most a band's slope step is divided by (its nodes grow as the square)
TEXEL_GAINS = (1.0, 2.0 ** 0.5, 2.0, 2.0 ** 1.5)  # the factors a band's texels may be made finer by
SIGMAS = 3.0  # the texel errors' spread (independent phases) counted this many standard deviations
PITCH = 0.5  # the predictions' grid: this many of the finest drawn level's lattice steps (least spacing) a sample


def projections(wv, group: int, view, pitch: float) -> dict:
    """``{(level, key): (P, Q)}``, each (C, N_v, N_u): the band's kept coefficients (``P``) and their squares (``Q``)
    summed into the cell of a grid across ``view`` (``pitch`` world units, from the model's centre; one grid for every
    band) that holds their support centres' orthographic projection along the view's axis."""
    g = wv.groups[group]
    # the cells counted from the model's centre: the same predictions wherever the model is placed
    axes, origin, cells = np.stack([view.u, view.v]), np.asarray(wv.origin, float), {}
    for b, part in zip(g.bands, g.band_slices()):
        index = np.stack(np.unravel_index(g.all_positions()[part] - b.start, b.shape), axis=1)
        centres = fine_to_world(support_centres(g.wavelet, b.key, b.level, index), g.wavelet.order, wv.shape,
                                wv.spacing, wv.origin)
        cells[(b.level, b.key)] = (np.rint((centres - origin) @ axes.T / pitch).astype(np.int64), g.values[:, part])
    kept = [ij for ij, _ in cells.values() if len(ij)]
    if not kept:
        return {}
    lo, hi = np.min([ij.min(axis=0) for ij in kept], axis=0), np.max([ij.max(axis=0) for ij in kept], axis=0)
    size = tuple(int(x) for x in hi - lo + 1)
    out = {}
    for band, (ij, values) in cells.items():
        flat = (ij[:, 1] - lo[1]) * size[0] + (ij[:, 0] - lo[0])
        out[band] = tuple(np.array([np.bincount(flat, weights=c ** power, minlength=size[0] * size[1])
                                    .reshape(size[::-1]) for c in values]) for power in (1, 2))
    return out


def error_kernels(wav, spacing, view, bands, pitch: float, lo, step, count) -> dict:
    """``{(level, key): (G, D_u, D_v, G_uu, G_vv)}`` on the grid of :func:`projections` (``pitch``), every band's on
    one box with its support centre at the same sample: each band's footprint ``G`` at the slope ``c`` one step in
    from the slope grid's (``lo``, ``step``, ``count``) node farthest from the view's axis (where footprints bend
    fastest), its second differences ``D_a`` over one slope step along a (``G(c + Δ_a) + G(c - Δ_a) - 2 G(c)``) and
    its second derivatives along u and v.  The footprints are the slices of the spectra along ``u + s_u n``,
    ``v + s_v n`` (:func:`~clwave.splat.spectral.fft_texture`, as
    :func:`~clwave.splat.perspective.sheared_footprints` makes them)."""
    d_xyz = np.array(spacing[::-1], float)
    lo, step, count = (np.asarray(x, float) for x in (lo, step, count))
    hi = lo + step * (count - 1)
    c = np.where(np.abs(lo) > np.abs(hi), lo + step, hi - step)
    slopes = [c, c + [step[0], 0.0], c - [step[0], 0.0], c + [0.0, step[1]], c - [0.0, step[1]]]
    axes = [(view.u + s_u * view.n, view.v + s_v * view.n) for s_u, s_v in slopes]
    # one period for all, wider than every support's oblique projection: no footprint wraps around
    nu, nv = (2 * int(np.ceil(max(float(np.abs(pair[i]) @ support_extent(wav, key, m, d_xyz))
                                  for m, key in bands for pair in axes) / (2.0 * pitch))) + 4 for i in (0, 1))
    out = {}
    for m, key in bands:
        g = np.stack([np.fft.fftshift(fft_texture(wav, key, m, d_xyz, a_u, a_v, nu, nv, nu * pitch, nv * pitch, 1))
                      for a_u, a_v in axes])
        g0 = np.pad(g[0], 1)
        out[(m, key)] = (g[0], g[1] + g[2] - 2.0 * g[0], g[3] + g[4] - 2.0 * g[0],
                         (g0[1:-1, 2:] + g0[1:-1, :-2] - 2.0 * g[0]) / pitch ** 2,
                         (g0[2:, 1:-1] + g0[:-2, 1:-1] - 2.0 * g[0]) / pitch ** 2)
    return out


def level_errors(wv, group: int, view, texels, lo, step, count) -> dict:
    """``{(level, approximation): (slope_plus, slope_minus, texel_mean, texel_variance)}``: images (C, N_v, N_u) on one
    grid across the view (:func:`projections`) of the predicted interpolation errors, relative to the image maximum
    (the module's doc): the slope errors where a read's phases along u and v have like and unlike signs, the texel
    errors' mean and variance (of the square's units), of each level's bands among
    ``texels`` (band -> texel (h_u, h_v), world units) of ``wv``'s group ``group`` in ``view`` (perspective) on the
    slope grid ``lo``, ``step``, ``count`` (u, v each), the approximation band apart.  Empty where no positive image
    is predicted."""
    g = wv.groups[group]
    pitch = PITCH * 2.0 ** min(m for m, _ in texels) * float(np.min(wv.spacing))
    sums = projections(wv, group, view, pitch)
    bands = [band for band in texels if band in sums]
    coarsest = max(b.level for b in g.bands)
    if (coarsest, "aaa") not in bands:
        return {}
    kernels = error_kernels(g.wavelet, wv.spacing, view, bands, pitch, lo, step, count)
    # the convolutions of a level's bands summed as the products of their spectra: one inverse FFT an image
    full = np.add(sums[bands[0]][0].shape[1:], kernels[bands[0]][0].shape) - 1
    shape = [scipy.fft.next_fast_len(int(k), real=True) for k in full]

    def spectrum(x):  # single precision: an estimate, twice as fast as double
        return scipy.fft.rfft2(np.asarray(x, np.float32), shape, axes=(-2, -1), workers=-1)

    def image(x):
        return scipy.fft.irfft2(x, shape, axes=(-2, -1), workers=-1)[..., :full[0], :full[1]]

    top = float(image(spectrum(sums[(coarsest, "aaa")][0]) * spectrum(kernels[(coarsest, "aaa")][0])).max(initial=0.0))
    if not top > 0:
        return {}
    parts = {}
    for band in bands:
        (signed, squares), (_, d_u, d_v, g_uu, g_vv) = sums[band], kernels[band]
        t_u, t_v = (h ** 2 * g for h, g in zip(np.broadcast_to(np.asarray(texels[band], float), 2), (g_uu, g_vv)))
        p, q = spectrum(signed), spectrum(squares)
        images = parts.setdefault((band[0], band[1] == "aaa"), [0.0] * 4)
        for i, (x, k) in enumerate(((p, d_u + d_v), (p, d_u - d_v), (p, t_u + t_v), (q, t_u ** 2 + t_v ** 2))):
            images[i] = images[i] + x * spectrum(k)
    return {level: (image(s) / (16.0 * top), image(s2) / (16.0 * top), image(t) / (48.0 * top),
                    image(t2) / (720.0 * top ** 2)) for level, (s, s2, t, t2) in parts.items()}


def predicted_error(errors, choice) -> float:
    """The largest predicted interpolation error (relative to the image maximum) of the levels' ``errors``
    (:func:`level_errors`) refined as ``choice`` (level -> (r, gain)): the slope errors of the levels with one ``r``
    summed with their signs (their splats are read at one place in one slope cell, at each of its corners' signs),
    those of different ``r`` in magnitude; the texel errors' mean summed with its sign and their spread in squares."""
    total = 0.0
    for r in {o[0] for o in choice.values()}:
        chosen = [level for level, o in choice.items() if o[0] == r]
        total = total + np.maximum(*(np.abs(sum(errors[level][i] for level in chosen)) for i in (0, 1))) / r ** 2
    mean = sum(errors[level][2] / o[1] ** 2 for level, o in choice.items())
    spread = sum(errors[level][3] / o[1] ** 4 for level, o in choice.items())
    return float((total + np.abs(mean) + SIGMAS * np.sqrt(np.maximum(spread, 0.0))).max())


def refined_bands(wv, group: int, view, texels, lo, step, count) -> dict:
    """``{(level, key): (r, gain)}`` for the bands ``texels`` of :func:`level_errors`: each level's bands (the
    approximation band on its own) with their slope step divided by ``r`` and their texels by ``gain`` (slope errors
    fall as ``r^2``, texel errors as ``gain^2``), chosen greedily: while the largest of the levels' predicted errors
    summed at each point (:func:`predicted_error`) exceeds :data:`SHARE`, the step (``r`` one more, or the next
    gain) of one level that lowers it most for the texels it adds (its footprints' widths over their texels, times
    ``gain^2`` and the nodes ``((k_u - 1) r + 1)((k_v - 1) r + 1)``), then the steps that later ones made needless
    taken back; ``(1, 1)`` for the levels never refined, and for every band of other than cubic footprints (the
    order the rule was measured on, docs/splatting.md §8)."""
    plain = {band: (1, 1.0) for band in texels}
    if wv.groups[group].wavelet.order != 4:
        return plain
    errors = level_errors(wv, group, view, texels, lo, step, count)

    def cost(o):  # a texture's nodes (r steps to each of the grid's) times its texels
        return float(np.prod((np.asarray(count) - 1) * o[0] + 1)) * o[1] ** 2

    def steps(o):  # the next refinements of a level refined as o: r one more, or the next texel gain
        r, gain = o
        return [(r + 1, gain)] * (r < MAX_REFINE) + [(r, g) for g in TEXEL_GAINS if g > gain][:1]

    def back(o):  # the steps back: r one less, or the texel gain before
        r, gain = o
        return [(r - 1, gain)] * (r > 1) + [(r, g) for g in TEXEL_GAINS if g < gain][-1:]

    wav, d_xyz = wv.groups[group].wavelet, np.array(wv.spacing[::-1], float)
    weight = dict.fromkeys(errors, 0.0)  # each level's texels: its footprints' widths over their texels
    for (m, key), h in texels.items():
        if (m, key == "aaa") in weight:
            extent = support_extent(wav, key, m, d_xyz)
            weight[(m, key == "aaa")] += float(np.prod([np.abs(a) @ extent for a in (view.u, view.v)])
                                               / np.prod(np.broadcast_to(np.asarray(h, float), 2)))
    choice = dict.fromkeys(errors, (1, 1.0))
    worst = predicted_error(errors, choice) if errors else 0.0
    while worst > SHARE:
        trials = [(worst - predicted_error(errors, choice | {level: o}), level, o) for level in choice
                  for o in steps(choice[level])]
        gain, level, o = max(((e / (weight[level] * (cost(o) - cost(choice[level]))), level, o)
                              for e, level, o in trials), default=(0.0, None, None))
        if not gain > 0:
            break
        choice[level] = o
        worst = predicted_error(errors, choice)
    while worst <= SHARE:  # then take back the steps that a later one made needless, the costliest first
        backs = [(weight[level] * (cost(choice[level]) - cost(o)), level, o) for level in choice
                 for o in back(choice[level]) if predicted_error(errors, choice | {level: o}) <= SHARE]
        if not backs:
            break
        _, level, o = max(backs)
        choice[level] = o
    return {(m, key): choice.get((m, key == "aaa"), (1, 1.0)) for m, key in texels}
