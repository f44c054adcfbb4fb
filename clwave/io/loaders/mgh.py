"""FreeSurfer MGH files (``.mgh``, and ``.mgz``: one gzipped) through nibabel, in RAS+ as NIfTI is."""

from __future__ import annotations

import gzip
import math

import numpy as np

from ...errors import FileFormatError
from .shared import (GZIP_MAGIC, UNEVEN, Declared, TimeSeries, as_array, check_declared_size, note, one_volume,
                     placeable, proxy_frame, to_canonical)

#: FreeSurfer's geometry of a file without one (MRIallocHeader: x_r = -1, y_s = -1, z_a = 1, coronal LIA), the
#: directions of i, j, k as rows, as MGH stores them (nibabel's default stores their transpose, LSP)
_LIA_MDC = [[-1, 0, 0], [0, 0, -1], [0, 1, 0]]
#: how far from 1 an Mdc row's length may be: float32 rounding, a writer's few digits; past it the header is wrong
#: (fuzz29: a row of length 699 made 839 mm voxels beside 1 mm, 89.9 degrees oblique)
MDC_ROUNDING = 1e-3


def read_mgh(path, chunks, fits=None, frame=None):
    """An MGH/MGZ volume through nibabel's ``MGHImage``: its header (version, dimensions, sample type, the data it
    declares against what the file or gzip stream holds) is checked before nibabel reads it, its vox2ras affine
    placed as a NIfTI's (:func:`.shared.to_canonical`), in millimetres.  A file whose geometry is not valid
    (``goodRASFlag`` 0) is FreeSurfer's default, coronal LIA 1 mm voxels centred on the origin, with a warning;
    of several frames (a time series) the one ``frame`` picks (:meth:`.shared.TimeSeries.pick`), read alone."""
    from nibabel.freesurfer.mghformat import MGHHeader, MGHImage
    from nibabel.openers import ImageOpener

    dims, frames, dtype, good = _check_header(path)
    with ImageOpener(path, "rb") as fh:  # nibabel.load leaves its header's file open
        header = MGHHeader.from_fileobj(fh)
    if not good:
        header["delta"], header["Mdc"], header["Pxyz_c"] = 1, _LIA_MDC, 0
    with np.errstate(over="ignore", invalid="ignore"):  # a delta or Mdc past float range: placeable() refuses it
        affine = header.get_affine()
    fix = "write the file again with its true geometry (e.g. nibabel's MGHImage of its voxels and affine)"
    if not placeable(affine):
        raise FileFormatError(f"{path}: its vox2ras (the header's delta, Mdc and Pxyz_c) is not finite or not "
                              f"invertible, or its voxels are more than {UNEVEN:g} times longer along one axis than "
                              f"another; {fix}")
    lengths = np.linalg.norm(np.asarray(header["Mdc"], float), axis=1)  # each row an axis's direction
    if np.any(np.abs(lengths - 1) > MDC_ROUNDING):
        raise FileFormatError(f"{path}: its Mdc (the axes' direction cosines) has rows of length "
                              f"{', '.join(f'{n:.3g}' for n in lengths)}, not 1 (delta is the voxel's size); {fix}")
    if not good:
        note(f"{path} has no valid geometry (goodRASFlag 0): FreeSurfer's default is assumed, coronal LIA with 1 mm "
             "voxels centred on the origin; set it (mri_convert, or nibabel's MGHHeader) if known")
    proxy = MGHImage.ImageArrayProxy(str(path), header, mmap=False)
    if frames > 1:
        tr = float(header["tr"])
        series = TimeSeries(f"{path} holds {frames} frames of {' x '.join(map(str, dims))} voxels", dims + (frames,),
                            dtype, frames, *((tr, "ms") if 0 < tr < math.inf else (None, None)))
        series.place(dims, affine)
        proxy = proxy_frame(proxy, series.pick(frame, path))
    else:
        one_volume(frame, path)
    try:
        data = as_array(proxy, chunks, fits=fits, path=path)
    except Declared as declared:  # describe(): its place from the header (a .mgz's, read whole)
        declared.place(dims, affine)
        raise
    return to_canonical(data, affine)


def _check_header(path):
    """``(dims, frames, dtype, goodRASFlag)`` of an MGH header, refused in one line where it is cut short, not MGH
    (its version), names no sample type MGH has, declares an axis of no voxel, or more data than the file (a .mgz:
    its gzip stream) holds; read here with Python's integers, since nibabel's int32 product of the dimensions wraps
    (2^30 x 3 x 4 voxels declared 0 bytes)."""
    from nibabel.freesurfer.mghformat import DATA_OFFSET, data_type_codes, header_dtype

    zipped = path.name.lower().endswith(".mgz")
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if zipped != (magic == GZIP_MAGIC):
        raise FileFormatError(f"{path} is {'not ' if zipped else ''}gzip-compressed, and a .mgz is a gzipped MGH file, "
                              f"a .mgh a plain one: name it {path.with_suffix('.mgh' if zipped else '.mgz').name}")
    with (gzip.open if zipped else open)(path, "rb") as fh:
        raw = fh.read(header_dtype.itemsize)
    if len(raw) < header_dtype.itemsize:
        raise FileFormatError(f"{path}: its MGH header is cut short ({len(raw)} of {header_dtype.itemsize} bytes); "
                              "the file is truncated")
    header = np.frombuffer(raw, header_dtype)[0]
    if int(header["version"]) != 1:
        raise FileFormatError(f"{path} is not an MGH file (its version field is {int(header['version'])}, MGH's is "
                              "1)")
    code = int(header["type"])
    if code not in data_type_codes.value_set():
        types = ", ".join(f"{c} {data_type_codes.label[c]}" for c in data_type_codes.value_set())
        raise FileFormatError(f"{path}: its MGH header names the sample type {code}, none MGH has ({types}); the "
                              "file is corrupt")
    *dims, frames = (int(n) for n in header["dims"])
    if min(dims + [frames]) < 1:
        raise FileFormatError(f"{path}: its MGH header declares {' x '.join(map(str, dims))} voxels in {frames} "
                              "frame(s); every axis needs at least one")
    dtype = np.dtype(data_type_codes.dtype[code])
    check_declared_size(path, DATA_OFFSET, math.prod(dims) * frames * dtype.itemsize, dims + [frames] * (frames > 1),
                        gzip=zipped)
    return tuple(dims), frames, dtype, bool(header["goodRASFlag"])
