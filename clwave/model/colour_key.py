"""A colour key (docs/model.md §5): a photo stack's background of one colour (a blue gel, ice, a grey table) made
transparent by the distance of each voxel's colour from it, when a colour volume is classified
(:class:`clwave.TransferFunction`'s ``key``).  The one home of that distance and its soft edge."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

#: the tolerance of a key given without one, a share of the colour's range (0 .. 1 once scaled): 0.1 is 25.5 of 255
DEFAULT_TOLERANCE = 0.1


def check_key(key, option=None):
    """None, "auto" or ``(r, g, b, tolerance)`` (floats; the tolerance None where not given) of a key ``(r, g, b)`` or
    ``(r, g, b, tolerance)`` in the volume's sample units (0 .. 255 for 8 bits); anything else an InputError, in the
    words of the command line's ``option`` too."""
    if key is None:
        return None
    if isinstance(key, str) and key.strip().lower() == "auto":
        return "auto"
    fix = "R,G,B or R,G,B,TOL in the stack's sample units (0 .. 255 for 8 bits), or auto"
    try:
        given = key.split(",") if isinstance(key, str) else list(key)
        values = [float(v) for v in (given[:3] if len(given) == 4 and given[3] is None else given)]  # a checked key's
    except (TypeError, ValueError, OverflowError):
        values = []
    if len(values) not in (3, 4) or not all(math.isfinite(v) and v >= 0 for v in values) or \
            (len(values) == 4 and values[3] <= 0):
        raise InputError(f"colour key {key!r} must be (r, g, b) or (r, g, b, tolerance) of numbers >= 0, a tolerance "
                         f"> 0, in the volume's sample units, or 'auto'", cli=option and f"{option} {key}: give {fix}")
    return tuple(values) + (None,) * (4 - len(values))


def auto_key(data) -> tuple:
    """The median colour of the voxels on the 12 edges of a colour volume's box ``data`` (z, y, x, c), in its sample
    units (a Dask array's edges computed): a photo stack's corners, where its background is."""
    edges = [data[:, [0, -1]][:, :, [0, -1]].reshape(-1, data.shape[3]),
             data[[0, -1]][:, :, [0, -1]].reshape(-1, data.shape[3]),
             data[[0, -1]][:, [0, -1]].reshape(-1, data.shape[3])]
    edges = np.concatenate([np.asarray(e) for e in edges])
    return tuple(float(v) for v in np.median(edges[:, :3], axis=0))


def key_weight(rgb, key, scale) -> np.ndarray:
    """The share (0 .. 1) of its opacity a voxel of colour ``rgb`` (n, 3), scaled to 0 .. 1, keeps under ``key`` (r,
    g, b, tolerance or None) in sample units whose range is ``scale`` (the colour's): 0 within the tolerance of the
    key colour (Euclidean distance in RGB on 0 .. 1), rising linearly to 1 at twice it."""
    colour = np.asarray(key[:3]) / scale
    tolerance = DEFAULT_TOLERANCE if key[3] is None else key[3] / scale
    distance = np.sqrt(((rgb - colour) ** 2).sum(axis=1))
    return np.clip(distance / tolerance - 1.0, 0.0, 1.0)
