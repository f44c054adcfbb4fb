"""The signs of a one-channel model's values, which line integrals (X-rays, radiographs) add: a model below 0 on the
whole (:func:`below_zero`, a CT in Hounsfield units) and one of both signs alike (:func:`warn_both_signs`, seismic
amplitudes, phase maps, difference volumes), whose integrals cancel (docs/coordinates.md §3)."""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, warn_outside

#: values of both signs alike: the lesser sign's reach at least this share of the greater's (seismic amplitudes,
#: phase and B-field components ~1; a cryo-EM map's noise floor, a CT's air against its bone, below it)
BOTH_SIGNS = 0.5

#: a model whose least value is at or below this, below 0 on the whole, is a CT in Hounsfield units (air is -1000),
#: which the command line's Hounsfield hint and the radiographs' refusal tell of already
HOUNSFIELD_AIR = -900.0


def below_zero(wv) -> bool:
    """Whether a one-channel model is below 0 on the whole: the sign of its integral, which is that of its coarsest
    approximation coefficients' sum (its details integrate to 0).  A thresholded attenuation rings below 0 near its
    edges, never on the whole; a CT in Hounsfield units is below 0 on the whole (air is -1000)."""
    group = wv.groups[0]
    return float(np.sum(group.values[0, group.band_slices()[0]], dtype=np.float64)) < 0


def warn_both_signs(wv) -> None:
    """A :class:`ClwaveWarning` where a one-channel model's values (its input's range less its subtraction) are of
    both signs alike (:data:`BOTH_SIGNS`): its line integrals cancel along the rays, and an X-ray of it shows what is
    left over, mostly noise.  The measure is the range a model keeps (a mass of each sign needs the voxels, which a
    model of a large file does not read back cheaply).  A CT in Hounsfield units (:data:`HOUNSFIELD_AIR`) is left to
    the warnings about it."""
    if wv.channels != 1 or getattr(wv, "value_range", None) is None:
        return
    lo, hi = (v - wv.subtracted for v in wv.value_range)
    if not (lo < 0 < hi and min(-lo, hi) >= BOTH_SIGNS * max(-lo, hi)) or lo <= HOUNSFIELD_AIR and below_zero(wv):
        return
    said = (f"the model's values run from {lo:.4g} to {hi:.4g}, both signs alike (seismic amplitudes, phase, a "
            f"difference): an X-ray adds them, so they cancel along each ray and it shows mostly what is left over; "
            f"{{}}")
    warn_outside(ClwaveWarning(said.format("for a picture of them ray trace with a transfer function of either "
                                           "sign's colours (transfer_function=), subtract a background all values lie "
                                           "above (subtract=), or load a CT with hu_to_mu=True"),
                               cli=said.format("for a picture of them give --method raytrace --tf FILE (a transfer "
                                               "function of either sign's colours), --subtract VALUE (a background "
                                               "all values lie above), or --hu-to-mu for a CT")))
