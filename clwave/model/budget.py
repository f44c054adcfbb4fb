"""The thresholding rules' arguments checked (``keep=``, ``threshold=``, ``noise=``, ``focus=``), how many coefficients
``keep=`` keeps, and the warnings where a model cannot give that many (docs/model.md §2): one home for the API and the
command line, which prints them in its own words (:class:`ClwaveWarning`'s ``cli``)."""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, InputError, finite_number, warn_outside


def kept_count(keep, n_voxels) -> int | None:
    """The coefficients ``keep=`` keeps: ``round(keep * n_voxels)``, at least 1; None (every coefficient) for
    ``keep=1``, since a model has more coefficients than voxels (B-splines reach past the volume's faces)."""
    return None if keep == 1 else max(1, int(round(keep * n_voxels)))


def warn_short_budget(keep, budget, approx, n_voxels):
    """Warn that ``keep=`` (``budget`` coefficients) is below the ``approx`` live coefficients of the approximation
    band, which ranks first: no detail, part of the band dropped; names the least keep that keeps the band whole."""
    e = 10.0 ** (np.floor(np.log10(approx / n_voxels)) - 2)  # three digits, rounded up
    least = np.ceil(approx / n_voxels / e) * e
    said = (f"{{}}{keep:g} keeps {budget:,} coefficients, fewer than the {approx:,} of the approximation band: "
            f"no detail is kept and part of the approximation is dropped; ")
    if least <= 1:
        said += f"{{}}{least:.3g} or more keeps it whole"
        api, cli = said.format("keep=", "keep="), said.format("--keep ", "--keep ")
    else:  # the band (its B-splines reach past the volume) outnumbers the voxels: only fewer levels hold it
        said += f"the band outnumbers the {n_voxels:,} voxels, so {{}}"
        api, cli = said.format("keep=", "pass a smaller levels="), said.format("--keep ", "give a smaller --levels")
    warn_outside(ClwaveWarning(api, cli=cli))


def warn_stored(wv, keep, source):
    """Warn where ``keep=`` (below 1, "every coefficient") asks for more coefficients than the model ``wv`` read from
    the file ``source`` holds: all it stores are used.  Not refused: a file holds fewer than its own ``keep`` where
    the rest were zero, and the file cannot tell which."""
    asked = None if keep is None else kept_count(keep, wv.n_voxels)
    stored = min(g.kept for g in wv.groups)
    if asked is None or stored >= asked:
        return
    said = (f"{{}}{keep:g} asks for {asked:,} coefficients, and {source} stores {stored:,} "
            f"({100 * stored / wv.n_voxels:.2f} % of the voxels): all of them are used (a file keeps no zero "
            f"coefficients, so it may hold fewer than its own {{}}; if it was compressed with a smaller {{}}, "
            f"compress again with a larger one for more detail)")
    warn_outside(ClwaveWarning(said.format("keep=", "keep", "keep"), cli=said.format("--keep ", "--keep", "--keep")))


def check_one_rule(keep, threshold, noise):
    """Refuse all but exactly one of :meth:`WaveletVolume.threshold`'s rules."""
    if sum(x is not None for x in (keep, threshold, noise)) != 1:
        raise InputError("give exactly one of keep= (fraction of voxels), threshold= (importance) or noise= (times "
                         "the noise level of each band)")


def check_thresholding(keep, threshold, focus, noise=None) -> tuple:
    """``(keep, threshold, focus, noise)`` of :meth:`WaveletVolume.threshold`, checked before any work (each
    message also in the command line's words)."""
    if keep is not None:
        keep = finite_number(keep, "keep")
        if not 0 < keep <= 1:
            raise InputError(f"keep={keep} must be a fraction of the voxels in (0, 1]",
                             cli=f"--keep {keep:g} must be a fraction of the voxels in (0, 1], e.g. 0.05 for 5 %")
    if threshold is not None:
        threshold = finite_number(threshold, "threshold")
        if threshold < 0:
            raise InputError(f"threshold={threshold} must be an importance >= 0",
                             cli=f"--threshold {threshold:g} must be an importance >= 0")
    if noise is not None:
        noise = finite_number(noise, "noise")
        if noise < 0:
            raise InputError(f"noise={noise} must be a multiple >= 0 of each band's noise level, e.g. 3",
                             cli=f"--noise {noise:g} must be a multiple >= 0 of each band's noise level, e.g. 3")
    if focus is not None:
        try:
            centre, sigma = focus
            centre = tuple(float(c) for c in centre)
            sigma = float(sigma)
        except (TypeError, ValueError):
            raise InputError("focus must be ((x, y, z), sigma) in world units") from None
        if len(centre) != 3 or not np.all(np.isfinite(centre)) or not (np.isfinite(sigma) and sigma > 0):
            raise InputError(f"focus {focus!r} needs a finite (x, y, z) centre and sigma > 0",
                             cli="--focus X,Y,Z needs a finite centre and --sigma a positive world length")
        focus = (centre, sigma)
    return keep, threshold, focus, noise
