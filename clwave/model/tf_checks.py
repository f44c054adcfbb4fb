"""The checks of a transfer function's parts (:class:`clwave.TransferFunction`): its points, window and opacity unit,
each a standard exception in one line naming the problem and the fix."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

FLOAT32_MAX = float(np.finfo(np.float32).max)


def check_points(points) -> np.ndarray:
    """``points`` as a read-only (n, 5) float64 array of rows (value, r, g, b, opacity): at least 2, finite, values
    strictly increasing, colours in [0, 1], opacities >= 0; anything else an InputError naming the first bad row."""
    try:
        p = np.array(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer past float's range
        raise InputError("transfer function points must be rows of 5 numbers "
                         "(value, r, g, b, opacity) within float's range") from None
    if p.ndim != 2 or p.shape[1] != 5:
        raise InputError(f"transfer function points must be rows (value, r, g, b, opacity), "
                         f"got an array of shape {p.shape}")
    if p.shape[0] < 2:
        raise InputError(f"transfer function needs at least 2 points, got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        row = int(np.nonzero(~np.all(np.isfinite(p), axis=1))[0][0])
        raise InputError(f"transfer function point {row} {p[row].tolist()} is not finite "
                         "(NaN or Inf); give finite numbers")
    beyond = np.any(np.abs(p[:, [0, 4]]) > FLOAT32_MAX, axis=1)  # the values and opacities classified in float32
    if beyond.any():
        row = int(np.argmax(beyond))
        raise InputError(f"transfer function point {row} {p[row].tolist()} is beyond float32's range (+-3.4e38), "
                         "in which clwave classifies: give smaller values and opacities (or a longer opacity unit)")
    bad = np.nonzero(np.diff(p[:, 0]) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(f"transfer function values must be strictly increasing: point {i + 1} "
                         f"({p[i + 1, 0]:g}) does not exceed point {i} ({p[i, 0]:g})")
    col = p[:, 1:4]
    if np.any((col < 0) | (col > 1)):
        row = int(np.nonzero(np.any((col < 0) | (col > 1), axis=1))[0][0])
        raise InputError(f"transfer function colour {col[row].tolist()} of point {row} is "
                         "outside [0, 1]; give r, g, b in [0, 1]")
    if np.any(p[:, 4] < 0):
        row = int(np.nonzero(p[:, 4] < 0)[0][0])
        raise InputError(f"transfer function opacity {p[row, 4]:g} of point {row} is negative; "
                         "opacity is an extinction per unit length, >= 0")
    p.flags.writeable = False
    return p


def check_opacity_unit(unit, option=None):
    """None (one voxel) or a finite length > 0 (world units), as a float; anything else an InputError, in the words
    of the command line's ``option`` too."""
    if unit is None:
        return None
    try:
        value = float(unit)
    except (TypeError, ValueError, OverflowError):
        value = math.nan
    from .geometry import WORLD_RANGE

    low, high = WORLD_RANGE  # the lengths clwave renders: 1e-320 made every opacity infinite
    if isinstance(unit, bool) or not low <= value <= high:
        fix = f"a length > 0 in world units (the spacing's), from {low:g} to {high:g}"
        raise InputError(f"opacity unit {unit!r} must be {fix}, or None for one voxel (the smallest spacing)",
                         cli=option and f"{option} {unit:g} must be {fix}; leave it out for one voxel")
    return value


def check_window(window, option=None, colour_map=None):
    """None, "auto" or a validated finite (lo, hi) with lo < hi; anything else is an InputError, in the words of the
    command line's ``option`` too (e.g. "--tf-window", whose text gave the window): the one home of the check of
    every window, transfer functions' and displays'.  An inverted ``--window`` is told to reverse the ``colour_map``
    given (grey where none is) instead."""
    if window is None:
        return None
    if isinstance(window, str):
        if window.strip().lower() == "auto":
            return "auto"
        raise InputError(f"window must be None, 'auto' or (lo, hi), got {window!r}")
    try:
        lo, hi = (float(w) for w in window)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"window must be None, 'auto' or (lo, hi), got {window!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        name = colour_map or "grey"
        reverse = name[:-2] if name.endswith("_r") else name + "_r"
        inverted = f" (inverted contrast: --colour-map {reverse})" if option == "--window" and lo > hi else ""
        raise InputError(f"window ({lo:g}, {hi:g}) must be two finite numbers (lo, hi) with lo < hi",
                         cli=option and f"{option} {lo:g},{hi:g} must be two finite numbers LO,HI with LO < HI"
                                        f"{inverted}")
    return (lo, hi)


#: A CT of a patient holds air (-1000 HU) and lung (-850 .. -500 HU) about or in it: a volume whose least value is
#: above this holds neither, and is no CT in Hounsfield units (an MRI's, a PET's values are 0 or more).
AIR_HU = -500.0


def not_hounsfield(name, lo, least, modality=None) -> str | None:
    """Why the CT preset ``name``, its window from ``lo`` (the input's units), does not fit a volume whose least value
    is ``least`` and whose ``modality`` (:attr:`~clwave.Volume.modality`) is known: of another modality than CT
    (a DICOM series' Modality says so); else (CT, or not known) where the preset's window reaches air (a window
    moved above it is the user's) and the volume's values do not (docs/model.md §5); None where it fits, or is no
    CT preset."""
    if not str(name).startswith("ct-"):
        return None
    if modality is not None and modality["name"] != "CT":
        return (f"the transfer function {name} is for CT in Hounsfield units, and this volume's modality is "
                f"{modality['name']} (its DICOM Modality), not CT (for it")
    if lo > AIR_HU or least <= AIR_HU:
        return None
    return (f"the transfer function {name} is for CT in Hounsfield units, and this volume's least value is "
            f"{least:.4g}, with no air (-1000) or lung (below {AIR_HU:g}): it may be no CT (an MRI")
