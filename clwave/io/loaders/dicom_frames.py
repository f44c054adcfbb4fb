"""Multi-frame DICOM files whose frames carry their positions: enhanced images (Enhanced CT, MR, ...) by their
per-frame functional groups, RT Dose by its grid frame offsets; placed as the slices of a folder are
(:func:`.dicom.place_slices`).  Other multi-frame files (ultrasound cines, secondary captures) are refused."""

from __future__ import annotations

import os

import numpy as np

from ...errors import FileFormatError
from .dicom import (check_attribute, check_pixel_data, check_rescale, dcmread, fill_padding, header_facts, mark_padding,
                    modality_of, padding, place_slices, rescaled, series_facts)
from .shared import Declared, check_whole

#: what converts a multi-frame file clwave cannot place into a volume it reads
CONVERTER = "convert it with dcm2niix (dcm2niix -o OUT_FOLDER FILE) and read the .nii"


def read_dicom_frames(paths, fits=None, where=None):
    """The frames of multi-frame DICOM files ``paths`` (one file, or the files of one series: a scanner's file per
    stack or phase, a large enhanced CT split) as slices of one volume, rescaled, its padding filled
    (:func:`.dicom.fill_padding`), in RAS (``(data, spacing, origin, obliquity, modality)``); ``where`` names them in
    messages (default: the one file).  Refused (naming dcm2niix) where a file's frames carry no positions, or the
    frames lie in several orientations or pixel spacings, or do not form one stack (:func:`.dicom.place_slices`)."""
    from pydicom.pixels import iter_pixels
    from pydicom.pixels.utils import pixel_dtype

    where = where or f"multi-frame DICOM file {paths[0]}"
    files = [(path, *_frames_of(path)) for path in paths]
    path, ds = files[0][:2]
    positions, cosines, pixel, slopes, intercepts = (np.concatenate([f[2][k] for f in files]) for k in range(5))
    convert = CONVERTER.replace("FILE", os.path.commonpath([p.parent for p in paths]) if len(paths) > 1 else str(path))
    if not np.allclose(cosines, cosines[0], atol=1e-4):
        raise FileFormatError(f"{where}: its frames lie in several orientations; {convert}")
    sizes = {(int(d.Rows), int(d.Columns)) for _, d, *_ in files}
    if not np.allclose(pixel, pixel[0]) or len(sizes) > 1:
        raise FileFormatError(f"{where}: its frames have several pixel spacings or image sizes; {convert}")
    frames, size = len(positions), (int(ds.Rows), int(ds.Columns))
    names = [f"frame {k + 1}" + (f" of {p.name}" if len(paths) > 1 else "")
             for p, d, *_ in files for k in range(int(d.NumberOfFrames))]

    def read(order):
        check_whole(paths[0], (frames, *size), pixel_dtype(ds), fits, streamed=True)
        data, rank, first = np.empty((frames, *size), np.float32), np.argsort(order), 0
        for path, d, *_ in files:
            declared, marks, count = int(d.NumberOfFrames), padding(d), 0
            for count, frame in enumerate(iter_pixels(path), 1):  # a frame at a time: one float32 copy is held
                if count > declared:
                    break
                k = first + count - 1
                data[rank[k]] = rescaled(path, frame.reshape(size), slopes[k], intercepts[k])
                mark_padding(frame.reshape(size), data[rank[k]], marks)
            if count != declared:  # pydicom yields what the pixel data holds: a short file leaves slices unwritten
                held = count if count < declared else f"more than {declared}"
                raise FileFormatError(f"{path} holds {held} frames of pixel data where it declares {declared} "
                                      f"(NumberOfFrames); the file is truncated or corrupt")
            first += declared
        return fill_padding(data, where)

    facts = dict(series_facts(ds), units=files[0][3])
    try:
        placed = place_slices(where, path, positions, cosines[0], tuple(pixel[0]), size, names, read, fits,
                              f"the {'file' if len(paths) == 1 else 'series'} may hold several acquisitions (echoes, "
                              f"phases, times), which dcm2niix separates: {convert}")
    except Declared as declared:  # describe(): what the headers say of the samples, and the series
        declared.dtype = np.dtype(np.float32)  # the frames as read: rescaled
        declared.facts = dict(header_facts(ds, zip(slopes, intercepts)), series=facts)
        raise
    return (*placed, modality_of(facts))


def _frames_of(path):
    """``(header, (positions, cosines, pixel spacing, slopes, intercepts), units)`` of a multi-frame file's frames
    (:func:`_enhanced`, :func:`_rt_dose`), its pixel data checked; refused where they carry no positions, or colour."""
    ds = dcmread(path, defer_size=1024)  # the pixels stay in the file: read by iter_pixels
    frames, kind = int(ds.NumberOfFrames), getattr(ds.get("SOPClassUID"), "name", "DICOM")
    if "PerFrameFunctionalGroupsSequence" in ds:
        geometry = _enhanced(path, ds, frames)
    elif "GridFrameOffsetVector" in ds and all(t in ds for t in ("ImagePositionPatient", "ImageOrientationPatient",
                                                                 "PixelSpacing")):
        geometry = _rt_dose(path, ds, frames)
    else:
        geometry = None
    if geometry is None or int(ds.get("SamplesPerPixel") or 1) != 1:
        why = "colour frames" if geometry is not None else "frames without positions (no per-frame functional " \
                                                            "groups or grid frame offsets)"
        raise FileFormatError(f"{path} is a multi-frame DICOM file ({kind}, {frames} frames) of {why}, not a volume "
                              f"clwave places; {CONVERTER.replace('FILE', str(path))}")
    check_pixel_data(path, ds)
    *geometry, units = geometry
    for tag, values in zip(("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing"), geometry):
        check_attribute(path, tag, values)
    check_rescale(path, ds, *geometry[3:])
    return ds, geometry, units


def _enhanced(path, ds, frames):
    """``(positions, cosines, pixel spacings, slopes, intercepts, units)`` per frame from the functional groups (a
    frame's own, else the shared ones), float32 rescale, and the first frame's RescaleType ("" where none); None where
    a frame has no position, orientation or spacing."""
    shared = ds.get("SharedFunctionalGroupsSequence") or [None]

    def value(k, sequence, tag, default=None):
        for groups in (ds.PerFrameFunctionalGroupsSequence[k], shared[0]):
            items = None if groups is None else groups.get(sequence)
            if items and tag in items[0]:
                return items[0][tag].value
        return ds.get(tag, default)

    if len(ds.PerFrameFunctionalGroupsSequence) != frames:
        raise FileFormatError(f"{path} is a multi-frame DICOM file of {frames} frames with "
                              f"{len(ds.PerFrameFunctionalGroupsSequence)} per-frame functional groups; the file is "
                              f"corrupt")
    rows = [(value(k, "PlanePositionSequence", "ImagePositionPatient"),
             value(k, "PlaneOrientationSequence", "ImageOrientationPatient"),
             value(k, "PixelMeasuresSequence", "PixelSpacing")) for k in range(frames)]
    if any(v is None for row in rows for v in row):
        return None
    scale = np.array([(value(k, "PixelValueTransformationSequence", "RescaleSlope", 1.0),
                       value(k, "PixelValueTransformationSequence", "RescaleIntercept", 0.0)) for k in range(frames)],
                     float).astype(np.float32)
    positions, cosines, pixel = (np.array([row[i] for row in rows], float) for i in range(3))
    units = str(value(0, "PixelValueTransformationSequence", "RescaleType", "") or "")
    return positions, cosines, pixel, scale[:, 0], scale[:, 1], units


def _rt_dose(path, ds, frames):
    """The same of an RT Dose grid: the first frame at ImagePositionPatient, the others along the normal by their
    GridFrameOffsetVector (relative to the first, which its first offset is), scaled by DoseGridScaling, in its
    DoseUnits."""
    cosines = np.array(ds.ImageOrientationPatient, float)
    offsets = np.array(ds.GridFrameOffsetVector, float)
    if offsets.shape != (frames,):
        raise FileFormatError(f"{path} is an RT Dose file of {frames} frames with {offsets.size} grid frame offsets; "
                              f"the file is corrupt")
    normal = np.cross(cosines[:3], cosines[3:])
    positions = np.array(ds.ImagePositionPatient, float) + (offsets - offsets[0])[:, None] * normal
    slopes = np.full(frames, float(ds.get("DoseGridScaling") or 1.0), np.float32)
    return (positions, np.tile(cosines, (frames, 1)), np.tile(np.array(ds.PixelSpacing, float), (frames, 1)), slopes,
            np.zeros(frames, np.float32), str(ds.get("DoseUnits") or ""))
