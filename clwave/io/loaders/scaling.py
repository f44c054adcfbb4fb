"""A file's linear scaling of its samples (NIfTI's ``scl_slope``/``scl_inter``, DICOM's rescale, FITS's
``BSCALE``/``BZERO``), checked by its header before a voxel is read."""

from __future__ import annotations

import numpy as np

from ...errors import FileFormatError


def check_scaling(where, names, slope, inter, stored, working=np.float32):
    """Refuse (``FileFormatError``) a linear scaling of a file's samples, ``slope`` times each plus ``inter`` (the
    header fields' ``names``), that maps every value a sample of the ``stored`` type can hold to one value of the
    ``working`` type (float32, clwave's; a FITS cube of 32 bits is read as float64): a slope of 0, or one that
    underflows (a NIfTI-2 ``scl_slope`` of 1e-310: every voxel 0, rendered blank); the volume would be one value
    however its stored values vary."""
    stored, working = np.dtype(stored), np.dtype(working)
    if stored.kind not in "iuf" or working.kind != "f":
        return
    span = np.iinfo(stored) if stored.kind in "iu" else np.finfo(stored)
    with np.errstate(over="ignore", invalid="ignore"):
        ends = (np.array([span.min, span.max], float) * float(slope) + float(inter)).astype(working)
    if ends[0] == ends[1]:
        value = float(ends[0]) + 0.0  # -0.0 said as 0
        raise FileFormatError(f"{where} has {names[0]} = {slope!r} and {names[1]} = {inter!r}, which map every "
                              f"{stored} sample to {value:g} in {working} (its volume would be one value); "
                              f"the header is corrupt: correct its {names[0]}")
