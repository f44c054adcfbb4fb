"""A voxel grid whose axes are not at right angles (a sheared affine: a CT's gantry tilt, DICOM slices shifted sideways
in proportion to their distance, or a NIfTI affine dcm2niix wrote without its tilt correction) resampled onto a
straight grid, which is what the renderers draw: the one home of that resampling (docs/coordinates.md §1)."""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np

#: A shear that moves the grid's far corner less than this many voxels is the rounding of a header's numbers (a
#: float32 sform), not a shear: the volume is misplaced by less than a tenth of a voxel, as a DICOM series' rounded
#: positions are (dicom.STRAY_PIXELS).
STRAY_VOXELS = 0.1


class Straight(NamedTuple):
    """The straight grid that holds a sheared one: its ``shape`` (ni, nj, nk) and index -> world ``affine``;
    ``shear`` (3 x 3) and ``low`` (3) map a sheared index p to the straight one ``shear @ p - low``; ``moved``: how
    far the shear moves the sheared grid's far corner (voxels, the largest along an axis); ``degrees``: the largest
    angle of a sheared axis from its straight one."""

    shape: tuple
    affine: np.ndarray
    shear: np.ndarray
    low: np.ndarray
    moved: float
    degrees: float


def straight_grid(shape, affine) -> Straight:
    """The straight grid of ``affine`` (4 x 4, index -> world) over a grid of ``shape`` (its first 3 axes), on the
    right-angled axes closest to the world's: the affine's 3 x 3 part, its columns in each of their 6 orders, is
    factored as Q R (QR, R's diagonal positive), whose Q keeps the first column's direction and the plane of the
    first two (a tilted series' rows and columns, or its rows and its stack along the table); the Q least oblique to
    the world's axes (the first of equals) is the straight grid's axes (in the file's order: axis i made from column
    i), R's diagonal its spacing (each axis's part of its column: a voxel keeps its volume) and the rest the shear
    and rotation undone; wider by the shifts."""
    m = affine[:3, :3]
    order, q, r = closest_axes(m)
    back = np.argsort(order)  # the straight axes in the file's order: axis i the one made from column i
    q, spacing = q[:, back], np.diag(r)[back]
    shear = (r / np.diag(r)[:, None])[np.ix_(back, back)]  # sheared index -> straight index, both in the file's order
    far = np.array(shape[:3], float) - 1
    corners = shear @ np.array(np.meshgrid(*[(0.0, n) for n in far], indexing="ij")).reshape(3, -1)
    low, high = np.floor(corners.min(axis=1)), np.ceil(corners.max(axis=1))
    straight = np.eye(4)
    straight[:3, :3] = q * spacing
    straight[:3, 3] = affine[:3, 3] + straight[:3, :3] @ low
    lengths = np.linalg.norm(m, axis=0)
    degrees = float(np.degrees(np.arccos(np.clip(spacing / lengths, -1.0, 1.0))).max())
    moved = float((np.abs(np.triu(r / np.diag(r)[:, None], 1)) @ far[list(order)]).max())
    return Straight(tuple(int(n) for n in high - low + 1), straight, shear, low, moved, degrees)


def closest_axes(m) -> tuple:
    """``(order, q, r)``: the 3 x 3 matrix ``m``'s columns in the ``order`` whose Q R factors (R's diagonal positive)
    have the Q least oblique to the world's axes (the first of equals); R's diagonal is a voxel's size along them."""
    frames = []
    for order in itertools.permutations(range(3)):
        q, r = np.linalg.qr(m[:, order])
        sign = np.where(np.diag(r) < 0, -1.0, 1.0)
        q, r = q * sign, r * sign[:, None]
        oblique = float(np.arccos(np.clip(np.abs(q).max(axis=0), -1.0, 1.0)).max())
        frames.append((round(oblique, 9), order, q, r))
    return min(frames, key=lambda f: f[0])[1:]


def unshear(data_ijk, grid: Straight, fill) -> np.ndarray:
    """``data_ijk`` (ni, nj, nk[, c]) on the straight ``grid`` (float32): linear interpolation, which never
    overshoots, of the data extended by ``fill`` (the volume's least value: air in a CT) where the sheared grid does
    not reach (scipy's "grid-constant": a straight voxel on the sheared grid's face, a rounding outside it, keeps
    the face's value, which "constant" would fill)."""
    from scipy.ndimage import affine_transform

    back = np.linalg.inv(grid.shear)  # straight index + low -> sheared index
    out = np.empty(grid.shape + data_ijk.shape[3:], np.float32)
    channels = data_ijk.reshape(data_ijk.shape[:3] + (-1,))
    for c in range(channels.shape[3]):
        out.reshape(grid.shape + (-1,))[..., c] = affine_transform(
            np.asarray(channels[..., c], np.float32), back, offset=back @ grid.low, output_shape=grid.shape,
            order=1, mode="grid-constant", cval=float(fill))
    return out
