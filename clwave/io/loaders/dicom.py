"""Folders of DICOM slices: one image series, sorted along its normal, checked to be a straight stack of even
slices, rescaled, in RAS+."""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ...errors import FileFormatError, InputError
from .shared import SUPPORTED, folder_files, read_slices, reading, to_canonical

# Sign of each world axis when converting to RAS; LPS is DICOM's patient space.
_LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
# A series is refused when a slice strays from a straight stack of even spacing by more than these fractions
# of a pixel (sideways: a gantry tilt) or of a slice gap (along the normal: a missing slice); below them the
# strays are rounding in the files' decimal positions, and the volume is misplaced by less than a tenth of a voxel
STRAY_PIXELS, STRAY_SLICES = 0.1, 0.1
# Attributes every slice of a DICOM image series needs
_DICOM_SLICE_TAGS = ("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing",
                     "Rows", "Columns", "PixelData")


def read_dicom_folder(folder, series, progress_bar, fits=None):
    """One DICOM series: slices sorted along their normal, rescaled, in RAS; refused unless they form a
    straight stack of evenly spaced slices (:func:`_check_straight`, :func:`_even_spacing`)."""
    uid, headers = _pick_series(folder, _dicom_image_series(folder), series)
    if len(headers) < 2:
        raise FileFormatError(f"DICOM series {uid} in {folder} has 1 slice; a volume needs "
                              "at least 2")
    cosines = np.array([h.ImageOrientationPatient for _, h in headers], float)
    if not np.allclose(cosines, cosines[0], atol=1e-4):
        raise FileFormatError(f"DICOM series {uid} in {folder} mixes slice orientations "
                              "(e.g. a localizer); move the odd slices out of the folder")
    # direction along a row (column index grows), along a column (row index grows)
    row_dir, col_dir = cosines[0, :3], cosines[0, 3:]
    normal = np.cross(row_dir, col_dir)
    positions = np.array([h.ImagePositionPatient for _, h in headers], float)
    distance = positions @ normal
    order = np.argsort(distance, kind="stable")
    gaps = np.diff(distance[order])
    if np.any(gaps < 1e-4):
        first, second = (headers[order[i]][0].name for i in (np.argmin(gaps), np.argmin(gaps) + 1))
        raise FileFormatError(
            f"DICOM slices {first} and {second} of series {uid} share one position; the series may "
            "hold several acquisitions (echoes, phases, times): split them into separate folders")
    dy, dx = (float(s) for s in headers[order[0]][1].PixelSpacing)  # row spacing, column spacing
    where = f"DICOM series {uid} in {folder}"
    _check_straight(where, positions[order], distance[order], normal, min(dx, dy))
    dz = _even_spacing(where, distance[order])

    data_zyx = read_slices([headers[i][0] for i in order], _dicom_pixels,
                            "reading DICOM slices", progress_bar, fits)
    # index (column, row, slice) -> LPS patient coordinates (mm)
    affine_lps = np.eye(4)
    affine_lps[:3, :3] = np.column_stack([row_dir * dx, col_dir * dy, normal * dz])
    affine_lps[:3, 3] = positions[order[0]]
    data_ijk = data_zyx.transpose((2, 1, 0) + tuple(range(3, data_zyx.ndim)))
    return to_canonical(data_ijk, _LPS_TO_RAS @ affine_lps)


def _check_straight(where, positions, distance, normal, pixel):
    """Refuse slices (sorted along ``normal``) whose positions shift sideways: a gantry tilt, which a
    straight stack of them would misplace (each slice the further, the further it is from the first)."""
    sideways = positions - np.outer(distance, normal)
    # a tilt is a drift linear along the normal; the positions' rounding in the files scatters about it
    t = distance - distance.mean()
    slope = t @ (sideways - sideways.mean(axis=0)) / max(float(t @ t), 1e-30)
    span = distance[-1] - distance[0]
    shift = float(np.linalg.norm(slope)) * span
    scatter = np.sqrt(np.mean((sideways - sideways.mean(axis=0) - np.outer(t, slope)) ** 2) * 3)
    if shift > STRAY_PIXELS * pixel and shift > 4 * scatter:
        raise FileFormatError(
            f"{where} is tilted: its slices shift {shift:.4g} mm sideways over {span:.4g} mm along their "
            f"normal (a gantry tilt of {np.degrees(np.arctan2(shift, span)):.3g} degrees), and clwave stacks "
            "slices straight; resample the series onto a straight grid first, e.g. with dcm2niix (it corrects "
            "gantry tilt) or 3D Slicer")


def _even_spacing(where, distance) -> float:
    """The slice gap of slices at ``distance`` (sorted) along the normal, refused unless every slice lies
    within :data:`STRAY_SLICES` of a gap of the evenly spaced grid fitted to them (least squares)."""
    k = np.arange(len(distance)) - (len(distance) - 1) / 2  # the grid fitted, the files' rounding about it
    dz = float(k @ (distance - distance.mean()) / (k @ k))
    stray = np.abs(distance - distance.mean() - dz * k).max() / dz
    if stray > STRAY_SLICES:
        gaps = np.diff(distance)
        median = float(np.median(gaps))
        i = int(np.argmax(np.abs(gaps - median)))
        raise FileFormatError(
            f"{where} is not evenly spaced: its slice gaps range from {gaps.min():.4g} to {gaps.max():.4g} mm, the "
            f"slices at {distance[i]:.4g} and {distance[i + 1]:.4g} mm along the normal are {gaps[i]:.4g} mm apart "
            f"where the median gap is {median:.4g} mm (a missing slice?); supply the complete series, or resample "
            "it onto even slices first (e.g. with 3D Slicer)")
    return float(dz)


def _dicom_image_series(folder):
    """Headers of the DICOM image series in ``folder``: ``{uid: [(path, header), ...]}``.

    Non-DICOM files are skipped, and so are series without any image slice
    (DICOMDIR, reports, presentation states).  A file of an image series that
    lacks a slice attribute is an error rather than a silently missing slice.
    """
    import pydicom
    from pydicom.misc import is_dicom
    from pydicom.uid import MediaStorageDirectoryStorage

    groups = defaultdict(list)
    for path in folder_files(folder):
        with reading(path):
            if not is_dicom(path):
                continue
            # defer_size: PixelData is noted but not read
            header = pydicom.dcmread(path, defer_size=1024)
        if "SeriesInstanceUID" in header:
            groups[str(header.SeriesInstanceUID)].append((path, header))
        elif header.file_meta.get("MediaStorageSOPClassUID") != MediaStorageDirectoryStorage:
            # every DICOM object but a DICOMDIR has one: the file was cut before it
            raise FileFormatError(f"DICOM file {path} has no SeriesInstanceUID; it may be "
                                  "truncated or corrupt: move it out of the folder")
    images = {uid: files for uid, files in groups.items()
              if any(all(tag in h for tag in _DICOM_SLICE_TAGS) for _, h in files)}
    if not images:
        raise FileFormatError(
            f"folder {folder} holds no TIFF slices and no DICOM image slices (files with "
            f"{', '.join(_DICOM_SLICE_TAGS)}); supported inputs: {SUPPORTED}")
    for uid, files in images.items():
        for path, header in files:
            missing = [tag for tag in _DICOM_SLICE_TAGS if tag not in header]
            if missing:
                raise FileFormatError(
                    f"DICOM file {path} of image series {uid} lacks {', '.join(missing)}; it may "
                    "be truncated or corrupt, or not a slice: move it out of the folder")
    return images


def _pick_series(folder, groups, series):
    """``(uid, [(path, header), ...])`` of the series chosen by ``series=`` (index or UID)."""
    uids = sorted(groups, key=lambda u: (int(getattr(groups[u][0][1], "SeriesNumber", 0) or 0), u))
    if series is None and len(uids) == 1:
        return uids[0], groups[uids[0]]
    listing = "; ".join(
        f"[{i}] {u} '{getattr(groups[u][0][1], 'SeriesDescription', '')}' "
        f"({len(groups[u])} slice{'s' if len(groups[u]) != 1 else ''})" for i, u in enumerate(uids))
    if series is None:
        found = f"{folder} holds {len(uids)} DICOM series: {listing}; pick one with "
        raise InputError(found + "series=<index or SeriesInstanceUID>",
                         cli=found + "--series INDEX or --series SERIES_INSTANCE_UID")
    if isinstance(series, (int, np.integer)) and 0 <= series < len(uids):
        return uids[series], groups[uids[series]]
    if str(series) in groups:
        return str(series), groups[str(series)]
    raise InputError(f"series={series!r} matches none of the DICOM series in {folder}: {listing}",
                     cli=f"--series {series} matches none of the DICOM series in {folder}: {listing}")


def _dicom_pixels(path):
    """One slice's pixels as float32 with RescaleSlope/RescaleIntercept applied."""
    import pydicom

    ds = pydicom.dcmread(path)
    if int(getattr(ds, "NumberOfFrames", 1) or 1) > 1:
        raise FileFormatError(f"{path} is a multi-frame DICOM file; clwave reads folders of "
                              "single-frame slices")
    pixels = ds.pixel_array.astype(np.float32)
    slope = float(getattr(ds, "RescaleSlope", 1.0))
    intercept = float(getattr(ds, "RescaleIntercept", 0.0))
    return pixels * np.float32(slope) + np.float32(intercept)
