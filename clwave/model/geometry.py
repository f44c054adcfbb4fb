"""The geometry every renderer shares (docs/coordinates.md, docs/model.md §4): the view frame of
paper eq. 31, the maps between world points and fine-voxel coordinates, and the supports of the
basis functions.  World vectors are (x, y, z); volume shapes, spacings and subband keys are in
array-axis order (z, y, x)."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .bspline import SplineWavelet, wavelet_for

#: the world lengths clwave renders: a voxel's spacing at least WORLD_RANGE[0], the volume's extent (spacing times
#: voxels) and its origin's coordinates at most WORLD_RANGE[1] in magnitude, so that lengths and their squares are
#: normal float32 numbers in the renderers' arithmetic (1e-18 and 1e17 render as 1 does, scaled: docs/coordinates.md
#: §1; 1e-308 divided by zero)
WORLD_RANGE = (1e-18, 1e18)


# ----------------------------------------------------------------------------- the view frame
def view_frame(azimuth: float, elevation: float) -> tuple:
    """The view frame ``(n, u, v)`` of paper eq. 31 for angles in degrees: n towards the camera,
    u right and v up in the image, ``u x v = n``.

    >>> n, u, v = view_frame(0.0, 0.0)
    >>> n.tolist(), u.tolist(), v.tolist()
    ([1.0, 0.0, 0.0], [-0.0, 1.0, 0.0], [-0.0, -0.0, 1.0])
    """
    a, b = np.radians(azimuth), np.radians(elevation)
    n = np.array([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)])
    u = np.array([-np.sin(a), np.cos(a), 0.0])
    v = np.array([-np.cos(a) * np.sin(b), -np.sin(a) * np.sin(b), np.cos(b)])
    return n, u, v


#: The anatomical views of a RAS+ volume (x the patient's right, y anterior, z superior; docs/coordinates.md §2): the
#: (azimuth, elevation) of a camera or X-ray source on that side of the patient, each drawn as radiographs and CT
#: slices are shown: anterior is the AP view (the patient's left on the image's right, head up), posterior the PA
#: (their right on the right), left and right the laterals (a left lateral: anterior on the image's left), inferior
#: an axial view as CT slices are shown (from the feet: anterior up, the patient's left on the right), superior
#: from above the head (anterior up, their right on the right).
VIEWS = {"anterior": (90.0, 0.0), "posterior": (-90.0, 0.0), "left": (180.0, 0.0), "right": (0.0, 0.0),
         "superior": (-90.0, 90.0), "inferior": (90.0, -90.0)}


def named_view(name) -> dict:
    """``dict(azimuth=, elevation=)`` of the anatomical view ``name`` (:data:`VIEWS`), for :class:`~clwave.Camera`
    and :class:`~clwave.ConeBeam`: ``Camera(**named_view("anterior"), size=256)``.

    >>> named_view("anterior")
    {'azimuth': 90.0, 'elevation': 0.0}
    """
    key = name.strip().lower() if isinstance(name, str) else None
    if key not in VIEWS:
        raise InputError(f"unknown view {name!r}; choose one of {', '.join(VIEWS)} (a RAS+ volume's sides)")
    return dict(zip(("azimuth", "elevation"), VIEWS[key]))


def orthonormal_frame(n, u, v) -> tuple:
    """Validate an orthonormal frame; components below 1e-13 (cos 90 deg) are snapped to 0."""
    vecs = []
    for name, vec in (("n", n), ("u", u), ("v", v)):
        a = np.asarray(vec, float).reshape(-1)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise InputError(f"view vector {name} must be 3 finite numbers (x, y, z), got {vec!r}")
        vecs.append(np.where(np.abs(a) < 1e-13, 0.0, a))
    gram = np.array(vecs) @ np.array(vecs).T
    if np.max(np.abs(gram - np.eye(3))) > 1e-6:
        raise InputError("n, u, v must be orthonormal (paper eq. 31; see clwave.model.geometry.view_frame)")
    return tuple(vecs)


# ----------------------------------------------------------------------------- world <-> fine voxels
def fine_to_world(fine_zyx, order: int, shape, spacing, origin) -> np.ndarray:
    """World points (..., 3) as (x, y, z) of fine-voxel coordinates (..., 3) in (z, y, x).

    Fine-voxel coordinates of a model of B-spline order j: ``x_a = (p_a - origin_a) / d_a +
    (n_a - 1) / 2 + j / 2``, so voxel centres sit at the peaks of their B-splines (docs/model.md §4).
    """
    world_zyx = (np.asarray(fine_zyx, float) - order / 2.0 - (np.array(shape, float) - 1) / 2.0) \
        * np.array(spacing, float)
    return world_zyx[..., ::-1] + np.asarray(origin)


def world_points(points) -> np.ndarray:
    """World points (N, 3) as (x, y, z), float64 (one point may be given as 3 numbers); one InputError for another
    shape, or for values that are not numbers or not finite (or masked: their stored values would be taken)."""
    if np.ma.is_masked(points):
        raise InputError(f"points is a masked array with {np.ma.count_masked(points)} masked value(s); give the "
                         f"points to evaluate alone, e.g. points[~points.mask.any(axis=1)]")
    try:
        pts = np.atleast_2d(np.asarray(points))
    except ValueError:  # a ragged list
        pts = np.empty(0, object)
    if pts.dtype.kind not in "biuf":
        raise InputError(f"points must be numbers, an (N, 3) array as (x, y, z), got {str(points)[:60]!r}")
    pts = pts.astype(np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3) as (x, y, z), got {np.shape(points)}")
    if not np.isfinite(pts).all():
        bad = int(np.count_nonzero(~np.isfinite(pts).all(axis=1)))
        raise InputError(f"{bad} of the {len(pts)} points are not finite (NaN or Inf): give finite (x, y, z)")
    return pts


def world_to_fine(points_xyz, order: int, shape, spacing, origin) -> np.ndarray:
    """Fine-voxel coordinates (..., 3) in (z, y, x) of world points (..., 3) as (x, y, z)."""
    p = np.asarray(points_xyz, float)[..., ::-1] - np.asarray(origin)[::-1]
    return p / np.array(spacing, float) + (np.array(shape, float) - 1) / 2.0 + order / 2.0


def world_to_fine_affine(order: int, shape, spacing, origin) -> tuple:
    """``(scale, offset)``, each (x, y, z): fine-voxel coordinates = world * scale + offset, per axis
    (the form the kernels take; :func:`world_to_fine` as one affine map)."""
    scale = 1.0 / np.array(spacing[::-1], float)
    offset = -np.asarray(origin) * scale + (np.array(shape[::-1], float) - 1) / 2.0 + order / 2.0
    return scale, offset


# ----------------------------------------------------------------------------- supports of the bases
def view_in_fine(view, scale, offset) -> tuple:
    """The eye (perspective; orthographic: the target) and the rays' direction in grid-0 fine coordinates
    (z, y, x)."""
    eye = ((view.eye if view.perspective else view.target) * scale + offset)[::-1]
    return eye, (-view.n * scale)[::-1]


def band_lattice(wav: SplineWavelet, key: str, level: int) -> tuple:
    """``(offset, step, support)`` of the basis functions of band ``(level, key)``, per array axis.

    Coefficient k's support is ``[offset + step k, offset + step (k + support))`` in fine-voxel
    coordinates of the wavelet's own order (``offset``, ``support``: (3,) in the key's (z, y, x)
    order; ``step = 2^level``); docs/model.md §4.
    """
    offset = np.array([wav.offset(letter, level) for letter in key], float)
    support = np.array([wav.support(letter) for letter in key], float)
    return offset, 2.0 ** level, support


def support_centres(wav: SplineWavelet, key: str, level: int, index_zyx) -> np.ndarray:
    """Fine-voxel (z, y, x) centres of the supports of coefficients ``index_zyx`` (..., 3) of a band."""
    offset, step, support = band_lattice(wav, key, level)
    return offset + step * (np.asarray(index_zyx, float) + support / 2.0)


def support_extent(wav: SplineWavelet, key: str, m: int, d_xyz) -> np.ndarray:
    """World edge lengths of the support box, (x, y, z): ``2^m S_a d_a``."""
    key_xyz = key[::-1]
    return np.array([2.0 ** m * wav.support(key_xyz[a]) * d_xyz[a] for a in range(3)])


def projected_halfwidths(wavelet, key: str, m: int, spacing_zyx, u, v) -> tuple:
    """Half-widths ``(W_u/2, W_v/2)`` of the tight projected support box, world units.

    ``W_u = 2^m sum_a |u_a| S_a d_a``: the projection of the support box on u.
    """
    wav = wavelet_for(wavelet)
    extent = support_extent(wav, check_key(key), int(m), spacing_xyz(spacing_zyx))
    return 0.5 * float(np.abs(np.asarray(u, float)) @ extent), 0.5 * float(np.abs(np.asarray(v, float)) @ extent)


def footprint_vanishes(key: str, n) -> bool:
    """psi along an axis parallel to n integrates to 0 along every line: T == 0."""
    key_xyz = key[::-1]
    return any(key_xyz[a] == "d" and abs(n[a]) > 1.0 - 1e-12 for a in range(3))


# ----------------------------------------------------------------------------- validation
def spacing_xyz(spacing_zyx) -> np.ndarray:
    """Checked voxel spacing ``(dz, dy, dx)`` as an (x, y, z) array."""
    s = np.asarray(spacing_zyx, float).reshape(-1)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError(f"spacing must be three positive numbers (dz, dy, dx), got {spacing_zyx!r}")
    return s[::-1].copy()


def check_key(key) -> str:
    """A checked subband key: 3 letters of 'a' (phi) / 'd' (psi) in (z, y, x) order."""
    if not isinstance(key, str) or len(key) != 3 or set(key) - {"a", "d"}:
        raise InputError(f"subband key must be 3 letters of 'a'/'d' in (z, y, x) order, got {key!r}")
    return key


def axis_turn(orientation) -> np.ndarray:
    """The 3 x 3 signed permutation that turns a ``(z, y, x)`` array's unit steps (column ``a``: array axis ``a``'s)
    into RAS+, of an input whose ``orientation`` is stated (one that carries none): three axis codes as nibabel
    writes them (``"LPS"``, ``"RAS"``), the directions its x, y and z index axes (array axes 2, 1, 0) point to, as
    ``nibabel.aff2axcodes`` gives them of a NIfTI's (x, y, z) axes; one InputError for anything else."""
    from nibabel.orientations import axcodes2ornt

    try:
        ornt = axcodes2ornt(tuple(orientation.upper()[::-1]))
    except (AttributeError, ValueError):
        ornt = None
    if ornt is None or len(ornt) != 3 or set(ornt[:, 0]) != {0, 1, 2}:
        raise InputError(f"orientation={orientation!r} must be three axis codes, one of L/R, one of A/P and one of "
                         f"I/S, the directions the array's x, y and z axes point to (nibabel's, e.g. 'LPS' or 'RAS')",
                         cli=f"--orientation {orientation} must be three letters, one of L/R, one of A/P and one of "
                             f"I/S, the directions the array's x, y and z axes point to (e.g. LPS or RAS)")
    turn = np.zeros((3, 3))
    turn[ornt[:, 0].astype(int), np.arange(3)] = ornt[:, 1]
    return turn


def turned(data, spacing_zyx, turn):
    """``(data, spacing_zyx)`` of a ``(z, y, x[, c])`` array turned into RAS+ by ``turn`` (:func:`axis_turn`): its
    axes permuted and flipped (a view; a Dask array stays lazy), the spacing with them; its centre stays put."""
    source = [int(np.flatnonzero(turn[r])[0]) for r in (2, 1, 0)]  # the array axis that becomes z, y, x
    flips = tuple(slice(None, None, -1) if turn[r, a] < 0 else slice(None) for r, a in zip((2, 1, 0), source))
    return data.transpose(source + list(range(3, data.ndim)))[flips], tuple(spacing_zyx[a] for a in source)


# ----------------------------------------------------------------------------- voxel ranges
def voxel_ranges(voxels) -> list:
    """``[(start, stop), ...]`` of three ranges of voxel indices, one an array axis (z, y, x), ``stop`` exclusive as
    Python's slices, either end None where left open: ``voxels`` a text "Z0:Z1,Y0:Y1,X0:X1" (an end left out:
    ``300:400,50:,:``) or three slices or pairs (an axis whole: None); one InputError otherwise."""
    texts = voxels.split(",") if isinstance(voxels, str) else None
    items = texts if texts is not None else list(voxels) if isinstance(voxels, (list, tuple)) else []
    ranges = []
    for item in items if len(items) == 3 else ():
        if isinstance(item, str):
            ends = [e.strip() for e in item.split(":")] if ":" in item else None
            ends = None if ends is None or len(ends) != 2 else [int(e) if e.lstrip("-").isdigit() else e or None
                                                                  for e in ends]
        elif isinstance(item, slice) and item.step in (None, 1):
            ends = [item.start, item.stop]
        else:
            ends = [None, None] if item is None else list(item) if isinstance(item, (list, tuple)) else None
        if ends is None or len(ends) != 2 or \
                not all(e is None or isinstance(e, (int, np.integer)) and not isinstance(e, bool) for e in ends):
            break
        ranges.append(tuple(None if e is None else int(e) for e in ends))
    if len(ranges) != 3:
        raise InputError(f"voxels {voxels!r} must be three ranges of whole voxel indices START:STOP (STOP excluded; an "
                         f"end left out: the array's) in the array's axis order, z, y, x, e.g. '300:400,50:100,:'")
    return ranges


def voxel_box(voxels, shape, spacing, origin, orientation=None) -> tuple:
    """``(lo, hi)``, world (x, y, z), of the box the voxels ``voxels`` (:func:`voxel_ranges`) of an input array take,
    their outer faces (a voxel the cell of its spacing about its centre), in the geometry of the model made of it:
    ``shape``, ``spacing`` (z, y, x) and ``origin`` (x, y, z) the model's, ``orientation`` the codes the input was
    turned into RAS+ by (:func:`clwave.load`'s ``orientation=``; None: none, its axes the model's).  One InputError
    for a range beyond the array or empty."""
    ranges = voxel_ranges(voxels)
    turn = np.eye(3)[::-1] if orientation is None else axis_turn(orientation)  # array axis a -> world axis
    lo, hi = np.empty(3), np.empty(3)
    for a, ((start, stop), name) in enumerate(zip(ranges, "zyx")):
        r = int(np.argmax(np.abs(turn[:, a])))  # the world axis (x, y, z) it lies along, the model's axis 2 - r
        n, step = shape[2 - r], float(spacing[2 - r])
        start, stop = 0 if start is None else start, n if stop is None else stop
        if not 0 <= start < stop <= n:
            raise InputError(f"voxels {start}:{stop} along the array's axis {a} ({name}) must lie in 0:{n}, the start "
                             f"below the stop")
        k0, k1 = (start, stop) if turn[r, a] > 0 else (n - stop, n - start)  # a flipped axis counts from the end
        lo[r], hi[r] = ((k - n / 2.0) * step + float(origin[r]) for k in (k0, k1))
    return tuple(lo.tolist()), tuple(hi.tolist())
