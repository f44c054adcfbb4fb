"""The named transfer functions of :meth:`clwave.TransferFunction.preset` (docs/model.md §5), each a
``(value, r, g, b, opacity)`` table and its default window; values in the input's units (HU for CT), however
the volume stores them (:attr:`clwave.Volume.subtracted`); and the rows of a matplotlib colormap
(:func:`colormap_points`)."""

import importlib.util
import sys

import numpy as np

from ..errors import InputError, reals, type_name


def _hu(points, lo, hi):
    """Preset rows written in data units -> the normalised axis of window (lo, hi)."""
    return tuple(((v - lo) / (hi - lo), r, g, b, a) for v, r, g, b, a in points)


# Presets: points on the normalised axis [0, 1] plus a default window (lo, hi) in
# data units mapping 0 -> lo and 1 -> hi ("auto": 0.5/99.5 percentiles).  Opacities
# are per opacity unit, one voxel unless given (the CT ones were tuned per mm on
# ~1 mm voxels: at 0.5 mm they are twice as dense per mm, docs/model.md §5).
PRESETS = {
    # CT bone, Hounsfield units: transparent below +150 HU, 0.5 a voxel from 700 HU.
    "ct-bone": dict(window=(-1000.0, 2000.0), points=_hu([
        (-1000.0, 0.85, 0.55, 0.40, 0.0),
        (150.0, 0.85, 0.55, 0.40, 0.0),
        (300.0, 0.95, 0.82, 0.65, 0.1),
        (700.0, 1.00, 0.95, 0.85, 0.5),
        (2000.0, 1.00, 1.00, 1.00, 0.5),
    ], -1000.0, 2000.0)),
    # CT soft tissue: fat (-100 HU) yellow and faint, muscle/organs (+40 HU) red,
    # bone (> +300 HU) white and denser; air and lung transparent below -200 HU.
    "ct-soft-tissue": dict(window=(-1000.0, 1000.0), points=_hu([
        (-1000.0, 0.95, 0.80, 0.55, 0.0),
        (-200.0, 0.95, 0.80, 0.55, 0.0),
        (-100.0, 0.95, 0.80, 0.55, 0.01),
        (40.0, 0.85, 0.35, 0.30, 0.03),
        (300.0, 0.95, 0.90, 0.85, 0.05),
        (1000.0, 1.00, 1.00, 1.00, 0.3),
    ], -1000.0, 1000.0)),
    # MRI (arbitrary units, auto window): background noise transparent, then a
    # warm grey ramp up to 0.06 a voxel at the 99.5th percentile.
    "mri": dict(window="auto", points=(
        (0.0, 0.60, 0.45, 0.40, 0.0),
        (0.1, 0.60, 0.45, 0.40, 0.0),
        (0.3, 0.75, 0.60, 0.55, 0.01),
        (0.6, 0.95, 0.85, 0.75, 0.03),
        (1.0, 1.00, 1.00, 1.00, 0.06),
    )),
    # Hydrogen phantom (max 1): low density transparent, blue -> yellow -> red,
    # up to 0.1 a voxel.  A ray through one lobe (n = 128 .. 256, spacing 1)
    # collects A = ∫alpha ≈ 2 .. 4; the torus (value 0.25) shows light blue.
    "hydrogen": dict(window=(0.0, 1.0), points=(
        (0.00, 0.05, 0.10, 0.60, 0.0),
        (0.05, 0.10, 0.25, 1.00, 0.0),
        (0.25, 0.20, 0.60, 1.00, 0.02),
        (0.55, 1.00, 0.90, 0.20, 0.05),
        (1.00, 1.00, 0.20, 0.05, 0.1),
    )),
    # Linear grey ramp, auto window: colour and opacity (0 .. 0.05 a voxel) rise together.
    "grey": dict(window="auto", points=(
        (0.0, 0.0, 0.0, 0.0, 0.0),
        (1.0, 1.0, 1.0, 1.0, 0.05),
    )),
    # Bright-field (stained sections, photo stacks on white): opacity rises as the
    # luminance falls, nothing from 0.9 of the window (the white background) up.  A
    # colour volume keeps its own RGB (only the opacity column applies); a scalar
    # one is drawn in greys.
    "brightfield": dict(window="auto", points=(
        (0.0, 0.10, 0.10, 0.10, 0.3),
        (0.5, 0.50, 0.50, 0.50, 0.1),
        (0.8, 0.80, 0.80, 0.80, 0.02),
        (0.9, 0.90, 0.90, 0.90, 0.0),
        (1.0, 1.00, 1.00, 1.00, 0.0),
    )),
    # A photo's own colour and alpha (an RGBA cut-out as PNG or TIFF store it, straight): opacity 0.5 a voxel times
    # its alpha (1 without one), colour its own RGB; what a 4-channel photo is classified by unless --tf names
    # another (docs/model.md §5).  A scalar volume is drawn as a white solid.
    "photo": dict(window=(0.0, 1.0), points=(
        (0.0, 1.0, 1.0, 1.0, 0.5),
        (1.0, 1.0, 1.0, 1.0, 0.5),
    )),
}


def is_colormap(value) -> bool:
    """Whether ``value`` is a matplotlib ``Colormap`` of one variable (its module loaded already: one given is; never
    imported here), not a bivariate or multivariate one, which maps pairs or tuples of values."""
    colors = sys.modules.get("matplotlib.colors")
    return colors is not None and isinstance(value, colors.Colormap)


def colormap_named(name) -> bool:
    """Whether ``name`` is a matplotlib colormap's name (False without matplotlib)."""
    try:
        import matplotlib
    except ImportError:
        return False
    return isinstance(name, str) and name in matplotlib.colormaps


def colormap_points(cmap, opacity) -> tuple:
    """``(points, name)`` of :meth:`clwave.TransferFunction.from_colormap`: the rows ``(t, r, g, b, opacity)`` of a
    matplotlib colormap (a ``Colormap`` or its name, looked up in ``matplotlib.colormaps``) at its ``N`` colours, t from
    0 to 1, the opacity rising from ``opacity[0]`` to ``opacity[1]`` times the colour's alpha."""
    if isinstance(cmap, str):
        if not colormap_named(cmap):
            raise InputError(f"{cmap!r} is no matplotlib colormap (e.g. 'viridis', 'magma', 'gray')"
                             if importlib.util.find_spec("matplotlib") else "a colormap's name needs matplotlib (pip "
                             "install matplotlib); or give the Colormap itself")
        import matplotlib

        cmap = matplotlib.colormaps[cmap]
    if not is_colormap(cmap):  # a bivariate one's ValueError came out of matplotlib
        raise InputError(f"from_colormap takes a matplotlib Colormap (of one variable) or its name, got "
                         f"{type_name(cmap)}")
    what = "two opacities (at the window's start, at its end), each >= 0"
    lo, hi = reals(opacity, "opacity", 2, what)
    if not (0 <= lo < np.inf and 0 <= hi < np.inf):  # else refused as a row of the table, which the caller never gave
        raise InputError(f"opacity={opacity!r} must be {what}, finite")
    t = np.linspace(0.0, 1.0, max(int(cmap.N), 2))
    rgba = np.asarray(cmap(t), dtype=np.float64)
    return np.column_stack([t, rgba[:, :3], (lo + (hi - lo) * t) * rgba[:, 3]]), str(getattr(cmap, "name", "colormap"))
