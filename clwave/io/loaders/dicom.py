"""Folders of DICOM slices: one image series, sorted along its normal, checked to be a stack of even slices (a
gantry tilt resampled onto a straight one), rescaled, in RAS+."""

from __future__ import annotations

import io
import math
import os
import re
import warnings
import zlib

import numpy as np

from ...device.memory import check_fits
from ...errors import FileFormatError
from ...model.volume import WORLD_RANGE
from .inflate import decompressed
from .scaling import check_scaling
from .shared import (Declared, check_float32_range, check_whole, largest_finite, note, read_slices,
                     reading, to_canonical)
from .shear import straight_grid, unshear

# Sign of each world axis when converting to RAS; LPS is DICOM's patient space.
_LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
# A series whose slices drift sideways along the normal by more than STRAY_PIXELS of a pixel is tilted (resampled),
# and one whose slices stray from an even spacing by more than STRAY_SLICES of a gap is uneven (a missing slice, two
# spacings: resampled); below them the strays are rounding in the files' decimal positions, and the volume is
# misplaced by less than a tenth of a voxel.  Slices that scatter about their drift by more than SCATTER_PIXELS of a
# pixel lie on no line, and a gap of more than MISSING times the smallest is no missing slice (MISSING - 1 of them in
# a row at most) but another acquisition: refused.
STRAY_PIXELS, STRAY_SLICES, SCATTER_PIXELS, MISSING = 0.1, 0.1, 0.5, 4
# Attributes every slice of a DICOM image series needs
_DICOM_SLICE_TAGS = ("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing",
                     "Rows", "Columns", "PixelData")


def read_dicom_folder(where, path, headers, progress_bar, fits=None):
    """The series ``where`` names (in messages), its single-frame files ``[(path, header)]`` under ``path`` (a
    folder, a tree, a DICOMDIR: :mod:`.dicom_tree` found them): slices sorted along their normal, rescaled, in RAS;
    resampled onto even slices along it where uneven (:func:`_even_slices`), refused unless they lie on a line
    (:func:`_drift`); a gantry tilt (slices shifted sideways in proportion to their distance) is resampled onto a
    straight stack (:func:`.shear.unshear`)."""
    if len(headers) < 2:
        raise FileFormatError(f"{where} has 1 slice; a volume needs at least 2")
    for file, header in headers:
        missing = [tag for tag in _DICOM_SLICE_TAGS if tag not in header]
        if missing:
            raise FileFormatError(f"DICOM file {file} of {where} lacks {', '.join(missing)}; it may be truncated or "
                                  "corrupt, or not a slice: move it out of the folder")
    for file, h in headers:
        check_pixel_data(file, h)
    for tag in ("ImageOrientationPatient", "ImagePositionPatient", "PixelSpacing"):
        for file, h in headers:
            check_attribute(file, tag, np.array(h.get(tag), float))
    for file, h in headers:
        check_rescale(file, h, float(getattr(h, "RescaleSlope", 1.0)), float(getattr(h, "RescaleIntercept", 0.0)))
    cosines = np.array([h.ImageOrientationPatient for _, h in headers], float)
    kinds, counts = np.unique(np.round(cosines, 4), axis=0, return_counts=True)
    common = kinds[np.argmax(counts)]
    odd = np.flatnonzero(~np.all(np.isclose(cosines, common, atol=1e-4), axis=1))
    if odd.size:
        shown = [", ".join(f"{v:g}" for v in c) for c in (cosines[odd[0]], common)]
        raise FileFormatError(f"{where} mixes slice orientations: {headers[odd[0]][0].name} has "
                              f"ImageOrientationPatient {shown[0]} where {counts.max()} of its {len(headers)} slices "
                              f"have {shown[1]} (a localizer?); move the odd slices out of the folder")
    _one_spacing(where, headers)
    positions = np.array([h.ImagePositionPatient for _, h in headers], float)
    first = headers[0][1]
    size = (int(first.Rows), int(first.Columns))

    def read(order):  # weighed from the headers, before a pixel is read (the slices rescaled to float32)
        check_whole(path, (len(order), *size), np.float32, fits)
        data = read_slices([headers[i][0] for i in order], _dicom_pixels, "reading DICOM slices", progress_bar)
        return fill_padding(data, where)

    try:
        return place_slices(where, path, positions, cosines[0],
                            tuple(float(s) for s in first.PixelSpacing), size,
                            [f"slice {file.name}" for file, _ in headers], read, fits,
                            "the series may hold several acquisitions (echoes, phases, times): split them into "
                            "separate folders")
    except Declared as declared:  # describe(): what the headers say of the samples too
        declared.facts = dict(header_facts(first, [(h.get("RescaleSlope", 1.0), h.get("RescaleIntercept", 0.0))
                                                   for _, h in headers]), series=series_facts(first))
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
    and ``size`` (rows, columns): sorted along their normal, resampled onto even slices where uneven
    (:func:`_even_slices`), refused unless on a line (:func:`_drift`), a gantry tilt resampled onto a straight stack
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
    dz, even = _even_slices(where, distance[order])
    tilted = bool(np.any(drift))
    count = len(order) if even is None else len(even)
    # index (column, row, slice) -> LPS patient coordinates (mm): a tilted series' slices shift by the drift
    affine_lps = np.eye(4)
    affine_lps[:3, :3] = np.column_stack([row_dir * dx, col_dir * dy, (normal + drift) * dz])
    affine_lps[:3, 3] = positions[order[0]]
    grid = straight_grid((size[1], size[0], count), affine_lps) if tilted else None
    straight = affine_lps if grid is None else grid.affine  # the straight stack's, wider by the shifts
    try:
        if tilted or even is not None:  # weighed before a slice is read
            check_whole(path, grid.shape[::-1] if tilted else (count, *size), np.float32, fits, resampled=True)
        data_zyx = read(order)
    except Declared as declared:  # describe(): its place from the headers
        declared.place(grid.shape if tilted else (size[1], size[0], count), _LPS_TO_RAS @ straight)
        raise
    if even is not None:
        data_zyx = _resample_along(data_zyx, distance[order], even)
    data_ijk = data_zyx.transpose((2, 1, 0) + tuple(range(3, data_zyx.ndim)))
    if tilted:
        depth = distance.max() - distance.min()
        note(f"{where} has a gantry tilt of {np.degrees(np.arctan(np.linalg.norm(drift))):.3g} degrees (its slices "
             f"shift {np.linalg.norm(drift) * depth:.4g} mm sideways over {depth:.4g} mm along their normal): "
             f"resampled straight onto the closest patient (RAS) axes, linearly, the new margins filled with its least "
             f"value")
        data_ijk = unshear(data_ijk, grid, data_ijk.min())
    return to_canonical(data_ijk, _LPS_TO_RAS @ straight)


def header_facts(first, rescales) -> dict:
    """What ``clwave info`` says of a series' samples from its ``first`` header: the type stored, the ``rescales``
    (each distinct ``(slope, intercept)``, in slice or frame order) and the padding range (:func:`padding`, stored
    values)."""
    from pydicom.pixels.utils import pixel_dtype

    marks = padding(first)
    return dict(stored_dtype=str(pixel_dtype(first)),
                rescale=[list(r) for r in dict.fromkeys((float(a), float(b)) for a, b in rescales)],
                padding=[] if marks is None else list(marks))


def series_number(header):
    """A header's SeriesNumber as an int, or None where it has none (it may be empty)."""
    try:
        return int(header.get("SeriesNumber"))
    except (TypeError, ValueError):
        return None


def series_facts(header) -> dict:
    """``clwave info``'s ``series`` from a header of it: its number, description, modality and UID, the ``study`` it
    belongs to (:func:`study_facts`), its ``patient`` (name and ID: PHI, which ``info`` shows on the user's terminal
    as DICOM viewers do, and nothing writes into an output, docs/coordinates.md §1) and the ``units`` of its values
    (RescaleType, else a PET's Units; "" where neither)."""
    return dict(number=series_number(header), description=_text(header, "SeriesDescription"),
                modality=_text(header, "Modality"), uid=_text(header, "SeriesInstanceUID"), study=study_facts(header),
                patient=dict(name=_text(header, "PatientName"), id=_text(header, "PatientID")),
                units=_text(header, "RescaleType") or _text(header, "Units"))


def modality_of(facts) -> dict | None:
    """:attr:`~clwave.Volume.modality` from :func:`series_facts`: None where the series has no Modality."""
    return dict(name=facts["modality"], units=facts["units"] or None) if facts["modality"] else None


def study_facts(header) -> dict:
    """The study a header's series belongs to, as PACS viewers list it: its ``date`` (YYYY-MM-DD, "" where none),
    ``time``, ``description``, ``accession`` number, ``id`` (StudyID) and ``uid``."""
    date = _text(header, "StudyDate")
    return dict(date=f"{date[:4]}-{date[4:6]}-{date[6:8]}" if re.fullmatch(r"\d{8}", date) else date,
                time=_text(header, "StudyTime"), description=_text(header, "StudyDescription"),
                accession=_text(header, "AccessionNumber"), id=_text(header, "StudyID"),
                uid=_text(header, "StudyInstanceUID"))


def _text(header, tag) -> str:
    return str(header.get(tag) or "").strip()


def series_name(facts) -> str:
    """A series as PACS viewers name it, from :func:`series_facts`: "series 2 'Thorax 1.0'" (its UID where it has
    neither number nor description)."""
    said = [] if facts["number"] is None else [str(facts["number"])]
    said += [f"'{facts['description']}'"] if facts["description"] else [] if said else [facts["uid"]]
    return " ".join(["series", *said])


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


def _even_slices(where, distance):
    """``(dz, even)``: the slice gap of slices at ``distance`` (sorted) along the normal, and None where every slice
    lies within :data:`STRAY_SLICES` of a gap of the evenly spaced grid fitted to them (least squares); else (a
    missing slice, two spacings) the positions of the even slices that :func:`_resample_along` makes, their gap the
    smallest that divides the span nearest the smallest gap, with a warning naming the gaps and where.  Refused
    where a gap exceeds :data:`MISSING` times the smallest."""
    k = np.arange(len(distance)) - (len(distance) - 1) / 2  # the grid fitted, the files' rounding about it
    dz = float(k @ (distance - distance.mean()) / (k @ k))
    if np.abs(distance - distance.mean() - dz * k).max() / dz <= STRAY_SLICES:
        return dz, None
    gaps = np.diff(distance)
    smallest, i = float(gaps.min()), int(np.argmax(gaps))
    if gaps[i] > MISSING * smallest:
        raise FileFormatError(
            f"{where} is not one evenly spaced acquisition: the slices at {distance[i]:.4g} and {distance[i + 1]:.4g} "
            f"mm along the normal are {gaps[i]:.4g} mm apart, more than {MISSING} times its smallest gap "
            f"({smallest:.4g} mm), more than {MISSING - 1} missing slices; supply the complete series, or split its "
            "acquisitions into separate folders")
    span = float(distance[-1] - distance[0])
    count = int(round(span / smallest)) + 1
    # runs of one gap (to a tenth of the smallest): where the spacing changes, or a slice is missing
    starts = [0] + [n for n in range(1, len(gaps)) if abs(gaps[n] - gaps[n - 1]) > STRAY_SLICES * smallest]
    runs = [f"{np.mean(gaps[a:b]):.4g} mm from {distance[a]:.4g} to {distance[b]:.4g} mm"
            for a, b in zip(starts, starts[1:] + [len(gaps)])]
    shown = ", ".join(runs[:6]) + (f" and {len(runs) - 6} more changes" if len(runs) > 6 else "")
    note(f"{where} is not evenly spaced: its slice gaps are {shown} along the normal; resampled onto {count} even "
         f"slices {span / (count - 1):.4g} mm apart, linearly between the slices it has")
    return span / (count - 1), distance[0] + span * np.arange(count) / (count - 1)


def _resample_along(data_zyx, distance, even):
    """Slices ``data_zyx`` at ``distance`` (sorted, along the normal) linearly interpolated at the positions
    ``even`` (within their range: nothing extrapolated), float32: a slice at a position that exists is kept."""
    upper = np.clip(np.searchsorted(distance, even, side="right"), 1, len(distance) - 1)
    lower = upper - 1
    weight = np.clip((even - distance[lower]) / (distance[upper] - distance[lower]), 0.0, 1.0)
    out = np.empty((len(even),) + data_zyx.shape[1:], np.float32)
    for n, (a, b, w) in enumerate(zip(lower, upper, weight)):
        out[n] = data_zyx[a] if w == 0 else data_zyx[b] if w == 1 else (1 - w) * data_zyx[a] + w * data_zyx[b]
    return out


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


#: a deflated dataset may inflate to the pixel data its attributes declare and this many bytes besides
MAX_ATTRIBUTES = 16 << 20


def dcmread(path, **options):
    """``pydicom.dcmread(path, **options)``, a deflated dataset weighed first (:func:`check_deflated`)."""
    import pydicom

    check_deflated(path)
    return pydicom.dcmread(path, **options)


def check_deflated(path):
    """Refuse a deflated dataset (transfer syntax 1.2.840.10008.1.2.1.99) that inflates past the pixel data its
    attributes declare (Rows, Columns, SamplesPerPixel, BitsAllocated, NumberOfFrames, read from its first
    :data:`MAX_ATTRIBUTES` bytes) and :data:`MAX_ATTRIBUTES` bytes besides: pydicom inflates all of it into memory
    before it reads one attribute (a 1 MB file held 1 GiB).  Inflated a megabyte at a time, its first
    :data:`MAX_ATTRIBUTES` bytes kept, the rest counted."""
    from pydicom.filereader import _read_file_meta_info, read_dataset, read_preamble
    from pydicom.uid import DeflatedExplicitVRLittleEndian

    with open(path, "rb") as fh:
        try:
            read_preamble(fh, False)
            syntax = _read_file_meta_info(fh).get("TransferSyntaxUID")
        except Exception:  # not a file of DICOM's format: pydicom's to name
            return
        if syntax != DeflatedExplicitVRLittleEndian:
            return
        pieces = decompressed(fh, lambda: zlib.decompressobj(-zlib.MAX_WBITS), b"", math.inf)
        head = bytearray()
        for piece in pieces:
            head += piece
            if len(head) >= MAX_ATTRIBUTES:
                break
        try:
            ds = read_dataset(io.BytesIO(head), False, True, stop_when=lambda tag, vr, length: tag == 0x7FE00010)
            pixels = math.prod(int(ds.get(name) or 1) for name in ("Rows", "Columns", "SamplesPerPixel",
                                                                    "NumberOfFrames")) * -(-int(ds.BitsAllocated) // 8)
        except Exception:  # attributes cut short in the first bytes, or no image: the bound without pixel data
            pixels = 0
        most, held = pixels + MAX_ATTRIBUTES, len(head)
        check_fits(most, f"inflating {path}, a deflated DICOM dataset that pydicom holds whole,",
                   "write it uncompressed first (DCMTK: dcmconv +te)")  # pixel data declared past the memory
        for piece in pieces:  # the rest of the stream, counted and dropped
            held += len(piece)
            if held > most:
                raise FileFormatError(f"DICOM file {path}: its deflated dataset inflates past {most:,} bytes, the "
                                      f"{pixels:,} of pixel data its attributes declare and {MAX_ATTRIBUTES:,} of "
                                      "others; it is not what it says (a decompression bomb): move it out of the "
                                      "folder")


def _dicom_pixels(path):
    """One slice's pixels (a single-frame file, read_dicom_folder checked) as float32 with RescaleSlope/RescaleIntercept
    applied, its padding NaN (:func:`mark_padding`).  Its header was read through :func:`dcmread` (the series'
    discovery, :mod:`.dicom_tree`), which weighed a deflated dataset: not again for each slice."""
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


# pip's names of the packages pydicom names a decoder's requirements by (their import names)
_PIP_NAMES = {"gdcm": "python-gdcm"}


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
        needs = decoder.missing_dependencies if decoder is not None else ["a decoder pydicom does not know"]
        pip = next((" ".join(_PIP_NAMES.get(name, name) for name in names if name != "numpy")
                    for names in ([re.split("[<>=]", p)[0] for p in plugin.split(" - requires ")[1].split(" and ")]
                                  for plugin in needs if " - requires " in plugin)), None)
        install = f"install one: pip install {pip} in clwave's environment (a clone set up by tools/setup.sh: " \
                  f".venv/bin/pip install {pip})" if pip else "install one"
        raise FileFormatError(f"DICOM file {path} holds pixel data in transfer syntax {syntax} ({syntax.name}), which "
                              f"no decoder installed here reads ({'; '.join(needs)}): {install}, or convert the series "
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


def check_rescale(path, ds, slopes, intercepts):
    """Refuse a DICOM file ``ds`` whose RescaleSlope or RescaleIntercept (each one, or one a frame) is not finite,
    beyond float32's range, or maps every value its pixels can hold to one (:func:`.scaling.check_scaling`)."""
    from pydicom.pixels.utils import pixel_dtype

    check_attribute(path, "RescaleSlope", slopes)
    check_attribute(path, "RescaleIntercept", intercepts)
    stored = pixel_dtype(ds)
    for slope, intercept in dict.fromkeys(zip(np.atleast_1d(slopes).tolist(), np.atleast_1d(intercepts).tolist())):
        check_scaling(f"DICOM file {path}", ("RescaleSlope", "RescaleIntercept"), slope, intercept, stored)


def check_attribute(path, tag, values):
    """Refuse a DICOM attribute no volume can be placed or scaled by: nan or inf; an ImageOrientationPatient that is
    not two perpendicular unit vectors (a slice's row and column directions); a PixelSpacing or ImagePositionPatient
    beyond the world lengths clwave renders (:data:`~clwave.model.volume.WORLD_RANGE`: the slices' gaps and drift
    overflowed); a RescaleSlope or RescaleIntercept beyond float32's range."""
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
    else:
        inside = np.abs(values).max() <= np.finfo(np.float32).max
        problem = None if inside else f"{tag} ({shown}) beyond float32's range"
    if problem:
        raise FileFormatError(f"DICOM file {path} has {problem}; the file is corrupt: correct its {tag} or move it "
                              f"out of the folder")
