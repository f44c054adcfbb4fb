"""Analytic test volumes (hydrogen 3d_z² orbital, Marschner–Lobb, 3-D Shepp–Logan): :func:`phantom`
samples one at the cell centres of an n³ grid of spacing 1; :func:`phantom_block` samples one block
of a grid of any shape (volumes bigger than memory, chunk by chunk: tools/make_zarr.py);
:func:`analytic` is the same formula at world points, the ground truth for line integrals (the same
float64 expressions, in order).

>>> vol = phantom("hydrogen", n=32)
>>> vol.shape, vol.spacing, float(vol.data.max()) <= 1.0
((32, 32, 32), (1.0, 1.0, 1.0), True)
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..errors import InputError
from ..device.memory import check_fits
from ..model.volume import Volume

NAMES = ("hydrogen", "marschner-lobb", "shepp-logan")

#: Half-width D of each phantom's domain cube [-D, D]³ (hydrogen in Bohr radii).
DOMAIN = {"hydrogen": 18.0, "marschner-lobb": 1.0, "shepp-logan": 1.0}

# Voxels evaluated per chunk: bounds the float64 temporaries (~8 arrays of this
# many doubles) whatever n is.
_CHUNK_VOXELS = 1 << 21

# --------------------------------------------------------------------------- hydrogen
# |psi_320|² ∝ (r² e^{-r/3} (3 cos²θ - 1))² = (e^{-r/3} (3z² - r²))².  The angular
# factor (3cos²θ - 1)² peaks at 4 on the z axis (θ = 0, π), where the radial part
# r⁴ e^{-2r/3} peaks at r = 6 (d/dr: 4/r = 2/3): the maximum over R³ is 4·6⁴·e^{-4}.
_HYDROGEN_MAX = 5184.0 * math.exp(-4.0)


def _hydrogen(x, y, z):
    r2 = (x * x + y * y) + z * z
    g = np.exp(-np.sqrt(r2) / 3.0) * (3.0 * z * z - r2)
    # the clamp only absorbs a possible last-bit overshoot exactly at the maximum
    return np.minimum(g * g / _HYDROGEN_MAX, 1.0)


# --------------------------------------------------------------------------- Marschner–Lobb
# Marschner & Lobb (1994), "An evaluation of reconstruction filters for volume rendering".
ML_FM = 6.0
ML_ALPHA = 0.25


def _marschner_lobb(x, y, z):
    rho_r = np.cos(2.0 * np.pi * ML_FM * np.cos(np.pi * np.sqrt(x * x + y * y) / 2.0))
    return ((1.0 - np.sin(np.pi * z / 2.0)) + ML_ALPHA * (1.0 + rho_r)) / (2.0 * (1.0 + ML_ALPHA))


# --------------------------------------------------------------------------- Shepp–Logan
# Source: M. Schabel, phantom3d.m (MATLAB File Exchange #9416), "modified_shepp_logan"
# (Toft's higher-contrast intensities).
#   A      a      b      c      x0     y0      z0     phi    theta  psi (degrees)
SHEPP_LOGAN = np.array([
    [1.0, 0.6900, 0.920, 0.810, 0.00, 0.0000, 0.00, 0.0, 0.0, 0.0],
    [-0.8, 0.6624, 0.874, 0.780, 0.00, -0.0184, 0.00, 0.0, 0.0, 0.0],
    [-0.2, 0.1100, 0.310, 0.220, 0.22, 0.0000, 0.00, -18.0, 0.0, 10.0],
    [-0.2, 0.1600, 0.410, 0.280, -0.22, 0.0000, 0.00, 18.0, 0.0, 10.0],
    [0.1, 0.2100, 0.250, 0.410, 0.00, 0.3500, -0.15, 0.0, 0.0, 0.0],
    [0.1, 0.0460, 0.046, 0.050, 0.00, 0.1000, 0.25, 0.0, 0.0, 0.0],
    [0.1, 0.0460, 0.046, 0.050, 0.00, -0.1000, 0.25, 0.0, 0.0, 0.0],
    [0.1, 0.0460, 0.023, 0.050, -0.08, -0.6050, 0.00, 0.0, 0.0, 0.0],
    [0.1, 0.0230, 0.023, 0.020, 0.00, -0.6060, 0.00, 0.0, 0.0, 0.0],
    [0.1, 0.0230, 0.046, 0.020, 0.06, -0.6050, 0.00, 0.0, 0.0, 0.0],
])
SHEPP_LOGAN.flags.writeable = False

# Amplitudes are multiples of 0.1: they are summed as integer tenths (exact in any
# order) and divided by 10 once, so e.g. 1 - 0.8 - 0.2 is exactly 0, not -5.6e-17.
_SL_TENTHS = np.rint(SHEPP_LOGAN[:, 0] * 10.0)


def _euler(phi_deg, theta_deg, psi_deg) -> np.ndarray:
    """phantom3d's Euler rotation matrix (applied to the coordinates: u = R·p)."""
    phi, theta, psi = np.radians([phi_deg, theta_deg, psi_deg])
    cphi, sphi = np.cos(phi), np.sin(phi)
    cth, sth = np.cos(theta), np.sin(theta)
    cpsi, spsi = np.cos(psi), np.sin(psi)
    return np.array([
        [cpsi * cphi - cth * sphi * spsi, cpsi * sphi + cth * cphi * spsi, spsi * sth],
        [-spsi * cphi - cth * sphi * cpsi, -spsi * sphi + cth * cphi * cpsi, cpsi * sth],
        [sth * sphi, -sth * cphi, cth],
    ])


_SL_ROT = [_euler(*row[7:10]) for row in SHEPP_LOGAN]


def _sl_quadform(e: int, x, y, z):
    """phantom3d's test value for ellipsoid e (inside where <= 1); broadcasts."""
    row, rot = SHEPP_LOGAN[e], _SL_ROT[e]
    if np.array_equal(rot, np.eye(3)):
        u0, u1, u2 = x, y, z           # == 1·x + 0·y + 0·z exactly; keeps the sum separable
    else:
        u0 = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z
        u1 = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z
        u2 = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z
    d0, d1, d2 = u0 - row[4], u1 - row[5], u2 - row[6]
    return (d0 * d0 / row[1] ** 2 + d1 * d1 / row[2] ** 2) + d2 * d2 / row[3] ** 2


def _sl_box(e: int):
    """Domain-space bounding box (lo, hi), x, y, z, of ellipsoid e."""
    row, rot = SHEPP_LOGAN[e], _SL_ROT[e]
    centre = rot.T @ row[4:7]            # u = R p  =>  p = R^T u
    half = np.sqrt((rot ** 2).T @ (row[1:4] ** 2))
    return centre - half, centre + half


def _shepp_logan(x, y, z):
    tenths = np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y), np.shape(z)))
    for e in range(len(SHEPP_LOGAN)):
        tenths += np.where(_sl_quadform(e, x, y, z) <= 1.0, _SL_TENTHS[e], 0.0)
    return tenths / 10.0


_FORMULAS = {"hydrogen": _hydrogen, "marschner-lobb": _marschner_lobb,
             "shepp-logan": _shepp_logan}


# --------------------------------------------------------------------------- public API
def _key(name) -> str:
    if not isinstance(name, str):
        raise InputError(f"phantom name must be a string, one of {', '.join(NAMES)}; got {name!r}")
    key = name.strip().lower().replace("_", "-")
    if key not in NAMES:
        raise InputError(f"unknown phantom {name!r}; choose one of {', '.join(NAMES)}")
    return key


def _check(name, n):
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
        raise InputError(f"phantom size n must be an integer >= 2 (voxels per axis), got {n!r}")
    if n < 2:
        raise InputError(f"phantom size n must be an integer >= 2 (voxels per axis), got {n}")
    return _key(name), int(n)


def _scale(key: str, n: int) -> float:
    """Domain units per world unit (per voxel): 2D/n."""
    return 2.0 * DOMAIN[key] / n


def analytic(name: str, n: int = 128) -> Callable[[np.ndarray], np.ndarray]:
    """The phantom's formula in world coordinates, for ground-truth comparisons.

    Parameters
    ----------
    name : {"hydrogen", "marschner-lobb", "shepp-logan"}
    n : int
        Grid size the world coordinates refer to (the same as :func:`phantom`):
        world point ``p`` is domain point ``p · 2D/n``.

    Returns
    -------
    f : callable
        ``f(points)`` takes world points ``(..., 3)`` as ``(x, y, z)`` and returns
        the float64 values ``(...)``; it evaluates the formula, never samples, and
        is defined (zero or smooth) everywhere in R³.

    >>> f = analytic("marschner-lobb", n=33)
    >>> float(f(np.zeros((1, 3)))[0])     # (1 - 0 + 0.25 (1 + cos 12π)) / 2.5
    0.6
    """
    key, n = _check(name, n)
    formula, scale = _FORMULAS[key], _scale(key, n)

    def f(points) -> np.ndarray:
        try:
            p = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError("points must be numbers of shape (N, 3) as world (x, y, z)") from None
        if p.ndim < 1 or p.shape[-1] != 3:
            raise InputError(f"points must have shape (N, 3) as world (x, y, z), got shape {p.shape}")
        u = p * scale
        return np.asarray(formula(u[..., 0], u[..., 1], u[..., 2]), dtype=np.float64)

    f.__name__ = f"analytic_{key.replace('-', '_')}"
    f.__doc__ = f"{key} phantom formula at world points (..., 3) (x, y, z) for grid size n={n}."
    return f


def phantom(name: str, n: int = 128) -> Volume:
    """An analytic phantom sampled at the cell centres of an ``n³`` grid.

    Parameters
    ----------
    name : {"hydrogen", "marschner-lobb", "shepp-logan"}
        ``hydrogen``: the 3d_z² orbital density |ψ₃₂₀|², z (array axis 0) the
        quantisation axis, on [-18, 18]³ Bohr radii, scaled so its maximum over R³
        is exactly 1.  ``marschner-lobb``: f_M = 6, α = 0.25 on [-1, 1]³.
        ``shepp-logan``: Schabel's 3-D modified Shepp–Logan head (phantom3d.m,
        10 ellipsoids, values in [0, 1]) on [-1, 1]³.
    n : int, >= 2
        Voxels per axis.

    Returns
    -------
    Volume
        Shape ``(n, n, n)``, spacing 1.0, origin 0.

    >>> phantom("shepp-logan", 16).data.max()
    np.float32(1.0)
    """
    key, n = _check(name, n)
    check_fits(4 * n ** 3, f"a {n}^3 phantom", "choose a smaller n")
    return Volume(_sample(key, (n, n, n), ((0, n),) * 3))


def phantom_block(name: str, shape, box=None) -> np.ndarray:
    """One block of a phantom sampled at the cell centres of a grid of any ``shape``.

    The phantom's domain cube [-D, D]³ spans the grid, each axis with its own
    scale 2D/n (a cube of voxels for a cubic shape).  Every block holds the
    samples the whole grid has there, bit for bit, so a volume bigger than
    memory can be written chunk by chunk; for ``shape = (n, n, n)`` the whole
    grid is ``phantom(name, n).data``.

    Parameters
    ----------
    name : {"hydrogen", "marschner-lobb", "shepp-logan"}
    shape : 3 ints
        Grid ``(nz, ny, nx)``, each >= 2.
    box : 3 slices, optional
        The block, ``(z, y, x)`` slices of the grid with step 1 (default: all of it).

    Returns
    -------
    ndarray, float32, the block's shape

    >>> whole = phantom("marschner-lobb", 8).data
    >>> bool(np.array_equal(phantom_block("marschner-lobb", (8, 8, 8), np.s_[2:5, :, 6:]), whole[2:5, :, 6:]))
    True
    """
    key = _key(name)
    try:
        shape = tuple(int(n) for n in shape)
        box = tuple(range(n)[s] for n, s in zip(shape, box or (slice(None),) * 3, strict=True))
    except (TypeError, ValueError):
        raise InputError(f"shape {shape!r} and box {box!r} must be 3 integers (nz, ny, nx) and 3 slices") from None
    if len(shape) != 3 or min(shape) < 2 or any(not isinstance(r, range) or r.step != 1 or not r for r in box):
        raise InputError(f"shape {shape} needs 3 axes of >= 2 voxels and box {box} 3 non-empty slices of step 1")
    check_fits(4 * math.prod(len(r) for r in box), f"a {' x '.join(str(len(r)) for r in box)} phantom block",
               "choose a smaller block")
    return _sample(key, shape, tuple((r.start, r.stop) for r in box))


def _sample(key, shape, box) -> np.ndarray:
    """float32 samples of phantom ``key`` on the grid ``shape`` in ``box`` ((start, stop) per axis z, y, x): the
    float64 formula at each cell centre, rounded once."""
    scales = [_scale(key, n) for n in shape]
    # domain coordinate per index; the grid is exactly symmetric, u[n-1-i] == -u[i]
    u = [(np.arange(n, dtype=np.float64) - (n - 1) / 2.0) * d for n, d in zip(shape, scales)]
    uz, uy, ux = (ui[a:b] for ui, (a, b) in zip(u, box))
    out = np.empty((len(uz), len(uy), len(ux)), dtype=np.float32)
    if key == "shepp-logan":
        _fill_shepp_logan(out, ux, uy, uz, scales[::-1])
    elif key == "hydrogen" and out.shape == tuple(shape):
        _fill_mirrored(out, ux, uy, uz, _hydrogen)
    else:
        _fill(out, ux, uy, uz, _FORMULAS[key])
    return out


def _fill(out, ux, uy, uz, formula):
    """out[i, j, k] = formula(ux[k], uy[j], uz[i]) in z chunks of bounded size."""
    x, y = ux[None, None, :], uy[None, :, None]
    step = max(1, _CHUNK_VOXELS // (len(uy) * len(ux)))
    for z0 in range(0, len(uz), step):
        out[z0:z0 + step] = formula(x, y, uz[z0:z0 + step, None, None])


def _fill_mirrored(out, ux, uy, uz, formula):
    """For a formula of x², y², z² only, on a whole grid: evaluate one octant, mirror it 8 ways.

    The grid is exactly symmetric and the formula sees only squares, so the
    mirrored samples are bit-identical to evaluating them.
    """
    halves, pairs = [], []
    for u in (uz, uy, ux):
        n = len(u)
        h = n // 2                        # first index of the upper half (the centre if n is odd)
        halves.append(u[h:])
        # upper half <- octant as is; lower half <- octant reversed (without the centre)
        lower = slice(n - 1 - h, n - 2 * h - 1 if n - 2 * h - 1 >= 0 else None, -1)
        pairs.append(((slice(h, n), slice(None)), (slice(0, h), lower)))
    octant = np.empty(tuple(len(half) for half in halves), dtype=out.dtype)
    _fill(octant, halves[2], halves[1], halves[0], formula)
    for oz, sz in pairs[0]:
        for oy, sy in pairs[1]:
            for ox, sx in pairs[2]:
                out[oz, oy, ox] = octant[sz, sy, sx]


def _fill_shepp_logan(out, ux, uy, uz, scales_xyz):
    """Adds each ellipsoid's tenths inside its bounding box only (+1 voxel margin)."""
    tenths = np.zeros(out.shape, dtype=np.int8)        # sums stay within -10..16
    for e in range(len(SHEPP_LOGAN)):
        lo, hi = _sl_box(e)
        # index ranges (x, y, z) whose centres can lie inside, one voxel of margin
        (x0, x1), (y0, y1), (z0, z1) = (np.searchsorted(u, (a - d, b + d)) for u, a, b, d in
                                        zip((ux, uy, uz), lo, hi, scales_xyz))
        if x1 <= x0 or y1 <= y0 or z1 <= z0:
            continue
        x, y = ux[None, None, x0:x1], uy[None, y0:y1, None]
        step = max(1, _CHUNK_VOXELS // ((y1 - y0) * (x1 - x0)))
        for zs in range(z0, z1, step):
            ze = min(zs + step, z1)
            inside = _sl_quadform(e, x, y, uz[zs:ze, None, None]) <= 1.0
            block = tenths[zs:ze, y0:y1, x0:x1]
            np.add(block, np.int8(_SL_TENTHS[e]), out=block, where=inside)
    np.divide(tenths, 10.0, out=out, dtype=np.float64, casting="unsafe")
