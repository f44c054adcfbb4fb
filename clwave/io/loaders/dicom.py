"""Folders of DICOM slices: one image series, sorted along its normal, checked to be a stack of even slices (a
gantry tilt resampled onto a straight one), rescaled, in RAS+."""

from __future__ import annotations

import os
import warnings
from collections import defaultdict

import numpy as np

from ...errors import FileFormatError, InputError
from ...model.volume import WORLD_RANGE
from .shared import (SUPPORTED, Declared, check_float32_range, check_whole, folder_files, largest_finite, note,
                     read_slices, reading, to_canonical)
from .shear import straight_grid, unshear

# Sign of each world axis when converting to RAS; LPS is DICOM's patient space.
_LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
# A series whose slices drift sideways along the normal by more than STRAY_PIXELS of a pixel is tilted (resampled),
# and one whose slices stray from an even spacing by more than STRAY_SLICES of a gap misses a slice (refused); below
# them the strays are rounding in the files' decimal positions, and the volume is misplaced by less than a tenth of
# a voxel.  Slices that scatter about their drift by more than SCATTER_PIXELS of a pixel lie on no line: refused.
STRAY_PIXELS, STRAY_SLICES, SCATTER_PIXELS = 0.1, 0.1, 0.5
# Attributes every slice of a DICOM image series needs
_DICOM_SLICE_TAGS = ("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing",
                     "Rows", "Columns", "PixelData")


def read_dicom_folder(folder, series, progress_bar, fits=None):
    """One DICOM series: slices sorted along their normal, rescaled, in RAS; refused unless they are evenly
    spaced along it (:func:`_even_spacing`) and lie on a line (:func:`_drift`); a gantry tilt (slices shifted
    sideways in proportion to their distance) is resampled onto a straight stack (:func:`.shear.unshear`)."""
    uid, headers = _pick_series(folder, _dicom_image_series(folder), series)
    for path, h in headers:  # before counting them: one such file is a volume clwave does not read, not one slice
        if int(getattr(h, "NumberOfFrames", 1) or 1) > 1:
            raise FileFormatError(f"{path} is a multi-frame DICOM file; clwave reads a folder of single-frame slices, "
                                  f"or a multi-frame file named itself: give {path}")
    if len(headers) < 2:
        raise FileFormatError(f"DICOM series {uid} in {folder} has 1 slice; a volume needs "
                              "at least 2")
    for path, h in headers:
        check_pixel_data(path, h)
    for tag in ("ImageOrientationPatient", "ImagePositionPatient", "PixelSpacing"):
        for path, h in headers:
            check_attribute(path, tag, np.array(h.get(tag), float))
    for path, h in headers:
        check_attribute(path, "RescaleSlope", float(getattr(h, "RescaleSlope", 1.0)))
        check_attribute(path, "RescaleIntercept", float(getattr(h, "RescaleIntercept", 0.0)))
    cosines = np.array([h.ImageOrientationPatient for _, h in headers], float)
    if not np.allclose(cosines, cosines[0], atol=1e-4):
        raise FileFormatError(f"DICOM series {uid} in {folder} mixes slice orientations "
                              "(e.g. a localizer); move the odd slices out of the folder")
    _one_spacing(f"DICOM series {uid} in {folder}", headers)
    positions = np.array([h.ImagePositionPatient for _, h in headers], float)
    first = headers[0][1]
    size = (int(first.Rows), int(first.Columns))

    def read(order):  # weighed from the headers, before a pixel is read (the slices rescaled to float32)
        check_whole(folder, (len(order), *size), np.float32, fits)
        data = read_slices([headers[i][0] for i in order], _dicom_pixels, "reading DICOM slices", progress_bar)
        return fill_padding(data, f"DICOM series {uid} in {folder}")

    try:
        return place_slices(f"DICOM series {uid} in {folder}", folder, positions, cosines[0],
                            tuple(float(s) for s in first.PixelSpacing), size,
                            [f"slice {path.name}" for path, _ in headers], read, fits,
                            "the series may hold several acquisitions (echoes, phases, times): split them into "
                            "separate folders")
    except Declared as declared:  # describe(): what the headers say of the samples too
        declared.facts = _header_facts([h for _, h in headers])
        raise


def _one_spacing(where, headers):
    """Refuse slices of several PixelSpacings (to a 1e-4 of it: the files' decimals), naming the first slice
    that differs from the most common: stacked, it would be drawn at the others' scale."""
    spacings = np.array([h.PixelSpacing for _, h in headers], float)
    kinds, counts = np.unique(spacings, axis=0, return_counts=True)
    common = kinds[np.argmax(counts)]
    odd = np.flatnonzero(~np.all(np.isclose(spacings, common, rtol=1e-4, atol=0), axis=1))
    if odd.size:
        path, shown = headers[odd[0]][0], ", ".join(f"{v:g}" for v in spacings[odd[0]])
        raise FileFormatError(f"{where} mixes pixel spacings: {path.name} has PixelSpacing {shown} mm where "
                              f"{counts.max()} of its {len(headers)} slices have {', '.join(f'{v:g}' for v in common)};"
                              f" move the odd slices out of the folder (or resample them first)")


def place_slices(where, path, positions, cosines, pixel, size, names, read, fits, shared):
    """The volume of slices at ``positions`` (n x 3, LPS mm; ``names[i]`` names slice i in messages) with the
    orientation ``cosines`` (a row's direction, then a column's), ``pixel`` spacing (between rows, between columns)
    and ``size`` (rows, columns): sorted along their normal, refused unless evenly spaced along it
    (:func:`_even_spacing`) and on a line (:func:`_drift`), a gantry tilt resampled onto a straight stack
    (:func:`.shear.unshear`); ``read(order)`` gives their pixels (n, rows, columns) in that order, once weighed
    (``fits``, by ``path``); ``shared``: why two slices may share a position, and the fix, for the caller's kind of
    input.  In RAS+, with spacing and origin."""
    # direction along a row (column index grows), along a column (row index grows)
    row_dir, col_dir = cosines[:3], cosines[3:]
    normal = np.cross(row_dir, col_dir)
    distance = positions @ normal
    order = np.argsort(distance, kind="stable")
    gaps = np.diff(distance[order])
    if np.any(gaps < 1e-4):
        first, second = (names[order[i]] for i in (np.argmin(gaps), np.argmin(gaps) + 1))
        raise FileFormatError(f"{first} and {second} of {where} share one position; {shared}")
    dy, dx = pixel  # row spacing, column spacing
    drift = _drift(where, positions[order], distance[order], normal, min(dx, dy))
    dz = _even_spacing(where, distance[order])
    tilted = bool(np.any(drift))
    # index (column, row, slice) -> LPS patient coordinates (mm): a tilted series' slices shift by the drift
    affine_lps = np.eye(4)
    affine_lps[:3, :3] = np.column_stack([row_dir * dx, col_dir * dy, (normal + drift) * dz])
    affine_lps[:3, 3] = positions[order[0]]
    grid = straight_grid((size[1], size[0], len(order)), affine_lps) if tilted else None
    straight = affine_lps if grid is None else grid.affine  # the straight stack's, wider by the shifts
    try:
        if tilted:  # weighed before a slice is read
            check_whole(path, grid.shape[::-1], np.float32, fits, resampled=True)
        data_zyx = read(order)
    except Declared as declared:  # describe(): its place from the headers
        declared.place(grid.shape if tilted else (size[1], size[0], len(order)), _LPS_TO_RAS @ straight)
        raise
    data_ijk = data_zyx.transpose((2, 1, 0) + tuple(range(3, data_zyx.ndim)))
    if tilted:
        depth = distance.max() - distance.min()
        note(f"{where} has a gantry tilt of {np.degrees(np.arctan(np.linalg.norm(drift))):.3g} degrees (its slices "
             f"shift {np.linalg.norm(drift) * depth:.4g} mm sideways over {depth:.4g} mm along their normal): "
             f"resampled onto a straight stack, linearly, the new margins filled with its least value")
        data_ijk = unshear(data_ijk, grid, data_ijk.min())
    return to_canonical(data_ijk, _LPS_TO_RAS @ straight)


def _header_facts(headers) -> dict:
    """What ``clwave info`` says of a series' samples from their headers: the type stored, the rescales (slope,
    intercept; each distinct pair, in slice order) and the padding range (:func:`padding`, stored values)."""
    from pydicom.pixels.utils import pixel_dtype

    rescales = [(float(getattr(h, "RescaleSlope", 1.0)), float(getattr(h, "RescaleIntercept", 0.0))) for h in headers]
    marks = padding(headers[0])
    return dict(stored_dtype=str(pixel_dtype(headers[0])), rescale=[list(r) for r in dict.fromkeys(rescales)],
                padding=[] if marks is None else list(marks))


def _drift(where, positions, distance, normal, pixel) -> np.ndarray:
    """The sideways drift (mm per mm along ``normal``) of slices sorted along it: a gantry tilt, 0 where it is
    the rounding of the files' positions.  Slices that scatter about a line by more than
    :data:`SCATTER_PIXELS` of a ``pixel`` are refused: no straight stack, tilted or not, holds them."""
    sideways = positions - np.outer(distance, normal)
    # a tilt is a drift linear along the normal; the positions' rounding in the files scatters about it
    t = distance - distance.mean()
    slope = t @ (sideways - sideways.mean(axis=0)) / max(float(t @ t), 1e-30)
    span = distance[-1] - distance[0]
    shift = float(np.linalg.norm(slope)) * span
    off = np.linalg.norm(sideways - sideways.mean(axis=0) - np.outer(t, slope), axis=1)
    if off.max() > SCATTER_PIXELS * pixel:
        raise FileFormatError(
            f"{where} does not lie on a line: the slice at {distance[np.argmax(off)]:.4g} mm along the normal is "
            f"{off.max():.4g} mm sideways off the line through the others (pixels of {pixel:.4g} mm); the folder may "
            "mix series or acquisitions: move the odd slices out of it")
    scatter = np.sqrt(np.mean(off ** 2) * 3)
    return slope if shift > STRAY_PIXELS * pixel and shift > 4 * scatter else np.zeros(3)


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
            f"folder {folder} holds no TIFF, PNG or JPEG slices and no DICOM image slices (files with "
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


def padding(ds):
    """``(least, greatest)`` stored value of the pixels ``ds`` marks as padding (outside the patient), or None: its
    PixelPaddingValue alone, or the range between it and PixelPaddingRangeLimit (PS3.3 C.7.5.1.1.2).  They are
    stored values, before the rescale."""
    if ds.get("PixelPaddingValue") is None:
        return None
    value, limit = int(ds.PixelPaddingValue), ds.get("PixelPaddingRangeLimit")
    limit = value if limit is None else int(limit)
    return min(value, limit), max(value, limit)


def mark_padding(stored, rescaled, marks):
    """``rescaled`` (float32) with NaN where ``stored`` lies in the padding range ``marks`` (:func:`padding`; None:
    none), for :func:`fill_padding`: a file with a padding value stores integers, so NaN marks nothing else."""
    if marks is not None:
        rescaled[(stored >= marks[0]) & (stored <= marks[1])] = np.nan
    return rescaled


def fill_padding(data, where):
    """``data`` (float32, rescaled) with its padding (the NaN :func:`mark_padding` left) set to the least other value
    of the series, in place: for a CT that is air, or near it, where the padding value (often -2000 or -3024 HU
    after the rescale) would be a shell denser than vacuum's negative, which an X-ray integrates (docs/
    coordinates.md §1).  A series all padding is refused."""
    padded = np.isnan(data)
    count = int(np.count_nonzero(padded))
    if count == data.size:
        raise FileFormatError(f"{where} marks every pixel as padding (PixelPaddingValue: outside the patient); it "
                              "holds no image: check its PixelPaddingValue and PixelPaddingRangeLimit")
    if count:
        least = float(np.min(data, initial=np.inf, where=~padded))
        data[padded] = least
        note(f"{where} marks {100 * count / data.size:.3g} % of its voxels as padding (outside the patient: "
             f"PixelPaddingValue): set to its least other value, {least:.6g}")
    return data


def _dicom_pixels(path):
    """One slice's pixels (a single-frame file, read_dicom_folder checked) as float32 with RescaleSlope/RescaleIntercept
    applied, its padding NaN (:func:`mark_padding`)."""
    import pydicom

    ds = pydicom.dcmread(path)
    slope, intercept = float(getattr(ds, "RescaleSlope", 1.0)), float(getattr(ds, "RescaleIntercept", 0.0))
    ds.pixel_array_options(allow_excess_frames=False)  # the one frame its header declares (checked: a single frame)
    with warnings.catch_warnings():  # pydicom's 2 lines on the bytes past it: the header's frame is what is read
        warnings.filterwarnings("ignore", "The pixel data is .* bytes long, which indicates it contains .* excess")
        stored = ds.pixel_array
    return mark_padding(stored, rescaled(path, stored, slope, intercept), padding(ds))


def rescaled(path, pixels, slope, intercept):
    """A slice's or frame's ``pixels`` times ``slope`` plus ``intercept`` as float32, refused (naming the file)
    where a value passes float32's range: computed in float64, one slice at a time."""
    values = pixels * float(slope) + float(intercept)
    check_float32_range(largest_finite(values), path)
    return values.astype(np.float32)


def check_pixel_data(path, ds):
    """Refuse a DICOM file ``ds`` (read with its pixel data deferred) whose pixel data no decoder here reads (a
    compressed transfer syntax without its plugin: named, with the packages that decode it), or, uncompressed, is
    shorter than its Rows, Columns, frames, samples and BitsAllocated declare or declared longer than the file, before
    a volume is weighed or allocated by them."""
    from pydicom.pixels import get_decoder
    from pydicom.pixels.utils import get_expected_length

    syntax = ds.file_meta.get("TransferSyntaxUID")
    if syntax is None:
        return
    try:
        decoder = get_decoder(syntax)
    except NotImplementedError:  # a private or unknown syntax
        decoder = None
    if decoder is None or not decoder.is_available:
        needs = "; ".join(decoder.missing_dependencies) if decoder is not None else "a decoder pydicom does not know"
        raise FileFormatError(f"DICOM file {path} holds pixel data in transfer syntax {syntax} ({syntax.name}), which "
                              f"no decoder installed here reads ({needs}): install one (pip), or convert the series "
                              f"with dcm2niix (dcm2niix -o OUT_FOLDER FOLDER) and read the .nii")
    rows, columns, allocated = (int(ds.get(k) or 0) for k in ("Rows", "Columns", "BitsAllocated"))
    stored = int(ds.get("BitsStored") or allocated)
    if min(rows, columns) < 1 or not 1 <= stored <= allocated:  # pydicom's refusals when it decodes, from the header
        raise FileFormatError(f"DICOM file {path} declares Rows {rows}, Columns {columns}, BitsAllocated {allocated} "
                              f"and BitsStored {stored}, which no image has (at least one row and column, at most "
                              f"BitsAllocated bits stored); the file is corrupt: correct its header or move it out of "
                              f"the folder")
    if syntax.is_encapsulated:
        return  # compressed frames: their decoder says what they hold
    with reading(path):
        element, expected = ds.get_item("PixelData", keep_deferred=True), get_expected_length(ds)
    held = element.length if hasattr(element, "length") else len(element.value)
    beyond = getattr(element, "value_tell", 0) + held - os.path.getsize(path)
    if beyond > 0:  # pydicom would allocate the length the element declares, then read the file short
        raise FileFormatError(f"DICOM file {path} declares {held:,} bytes of pixel data, {beyond:,} more than the file "
                              f"holds; the file is truncated or its header is wrong")
    if held < expected:
        raise FileFormatError(f"DICOM file {path} holds {held:,} bytes of pixel data where its header declares "
                              f"{expected:,} (Rows {ds.Rows}, Columns {ds.Columns}, NumberOfFrames "
                              f"{ds.get('NumberOfFrames') or 1}, BitsAllocated {ds.BitsAllocated}); the file is "
                              f"truncated or its header is wrong")


def check_attribute(path, tag, values):
    """Refuse a DICOM attribute no volume can be placed or scaled by: nan or inf; an ImageOrientationPatient that is
    not two perpendicular unit vectors (a slice's row and column directions); a PixelSpacing or ImagePositionPatient
    beyond the world lengths clwave renders (:data:`~clwave.model.volume.WORLD_RANGE`: the slices' gaps and drift
    overflowed); a RescaleSlope or RescaleIntercept beyond float32's range, or a RescaleSlope of 0."""
    values = np.atleast_1d(np.asarray(values, float))
    shown, low, high = ", ".join(map(str, values[:12])), *WORLD_RANGE
    count = {"ImageOrientationPatient": 6, "ImagePositionPatient": 3, "PixelSpacing": 2}.get(tag, 1)
    if values.size == 0 or values.size % count:
        problem = f"{tag} ({shown}) of {values.size} values, not {count}"
    elif not np.all(np.isfinite(values)):
        problem = f"a non-finite {tag} ({shown})"
    elif tag == "ImageOrientationPatient":
        rows = values.reshape(-1, 2, 3)
        with np.errstate(over="ignore"):  # a huge one: not a unit vector
            unit = np.allclose(np.linalg.norm(rows, axis=2), 1, atol=1e-3)
            perpendicular = np.allclose(np.sum(rows[:, 0] * rows[:, 1], axis=1), 0, atol=1e-3)
        problem = None if unit and perpendicular else f"{tag} ({shown}), not two perpendicular unit vectors"
    elif tag in ("PixelSpacing", "ImagePositionPatient"):
        inside = (values.min() >= low if tag == "PixelSpacing" else True) and np.abs(values).max() <= high
        problem = None if inside else f"{tag} ({shown}) beyond the world lengths clwave renders ({low:g} to {high:g})"
    elif tag == "RescaleSlope" and not np.all(values):
        problem = "RescaleSlope 0, which maps every pixel to the intercept"
    else:
        inside = np.abs(values).max() <= np.finfo(np.float32).max
        problem = None if inside else f"{tag} ({shown}) beyond float32's range"
    if problem:
        raise FileFormatError(f"DICOM file {path} has {problem}; the file is corrupt: correct its {tag} or move it "
                              f"out of the folder")
