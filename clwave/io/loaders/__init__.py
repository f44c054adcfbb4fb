"""Read volumes from files: one :func:`load` for every supported format.

The result is a (z, y, x[, c]) float32 :class:`~clwave.model.volume.Volume`; medical formats
(NIfTI, FreeSurfer MGH, NRRD, DICOM) are put in the canonical RAS+ orientation with spacing and origin in scanner
millimetres, FITS cubes on the sky (north up, east left, in pixels), SEG-Y cubes time down, the others keep their
array axes (docs/coordinates.md §1).  Zarr, OME-Zarr and HDF5 stores, and large .npy, .raw, .nii, .mgh, MRC, FITS and
TIFF files (and folders of TIFF slices), are read chunk by chunk as Dask arrays (docs/chunked.md §1).

One module per format family (``raw``: .raw and .npy; ``nifti``, ``mgh``, ``mrc``, ``fits``, ``nrrd``, ``tiff``,
``slices``: folders of TIFF, PNG or JPEG slices, ``dicom``, ``hdf5``, ``zarr``: Zarr and OME-Zarr, ``segy``), each
with its ``read_*``; ``shared`` holds what they share.
"""

from __future__ import annotations

import os
import re
from functools import partial
from pathlib import Path

import numpy as np

from ...errors import ClwaveError, FileFormatError, InputError, file_name, finite_number, flag, float32_number
from ...model.geometry import axis_turn
from ...model.labels import looks_like_labels
from ...model.volume import Volume, check_placement, is_dask
from . import (dicom, dicom_frames, dicom_tree, fits as fits_cube, hdf5, mgh, mrc, nifti, nrrd, raw, segy, slices, tiff,
               zarr)
from .shared import (SUPPORTED, Declared, TimeSeries, check_chunks, check_frame, folder_files, not_a_file, one_volume,
                     reading, to_float32)

__all__ = ["load", "describe", "world_unit", "in_ras", "DESCRIBED", "SUPPORTED", "RAS_FORMATS"]

_FILE_KINDS = {".npy": "npy", ".nii": "nifti", ".nii.gz": "nifti", ".mgh": "mgh", ".mgz": "mgh", ".nrrd": "nrrd",
               ".nhdr": "nrrd", ".tif": "tiff", ".tiff": "tiff", ".raw": "raw",
               ".h5": "hdf5", ".hdf5": "hdf5", ".hdf": "hdf5"} | dict.fromkeys(mrc.MRC_SUFFIXES, "mrc") \
    | dict.fromkeys(fits_cube.FITS_SUFFIXES, "fits") | dict.fromkeys(segy.SEGY_SUFFIXES, "segy")
#: the formats put in RAS+ (their origin and spacing in scanner millimetres; the others keep their array axes)
RAS_FORMATS = ("nifti", "mgh", "nrrd", "dicom", "dicom-frames")
#: a folder of slices, one file a slice: its kind by their format (docs/coordinates.md §1)
_SLICE_FOLDERS = tuple(f"{name.lower()}-folder" for name in slices.SLICE_SUFFIXES)
# 'file.h5:/path/in/file' or 'store.zarr:/path': the last ':' after such a suffix
_INNER_PATH = re.compile(r"(.*\.(?:h5|hdf5|hdf|zarr)):(.*)", re.IGNORECASE | re.DOTALL)
# Options that apply to some kinds of input only: those kinds, in words
_ONLY_FOR = {"shape": (("raw",), ".raw files"), "dtype": (("raw", "mrc"), ".raw files and MRC maps of bytes"),
             "byte_order": (("raw",), ".raw files"), "series": (("dicom",), "DICOM folders"),
             "level": (("zarr",), "OME-Zarr images"),
             "frame": (("nifti", "mgh", "tiff", "zarr", "fits"), "time series (NIfTI, MGH, TIFF, OME-Zarr and FITS "
                                                                 "files)")}


def load(path, *, shape=None, dtype=None, spacing=None, byte_order=None, series=None, level=None, frame=None,
         chunks=None, nan=None, subtract=0.0, hu_to_mu=False, mu_water=0.0193, progress_bar=None,
         fits=None, orientation=None, unit=None, origin=None, labels=None) -> Volume:
    """Load a volume file or folder as a :class:`Volume` (RAS+ for medical data).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy``, ``.nii``, ``.nii.gz``, FreeSurfer's ``.mgh``, ``.mgz``, ``.nrrd``, ``.nhdr``, a multi-page
        ``.tif``/``.tiff``, a folder of 2-D TIFF, PNG or JPEG slices of one format
        (grey, RGB or RGBA; stacked in natural name order: ``slice2`` before
        ``slice10``), a folder of DICOM files (other files in it are ignored), a folder of
        folders of them (a CD's top, a study) or a ``DICOMDIR``, a
        multi-frame DICOM file whose frames carry positions
        (enhanced CT/MR, RT Dose), ``.raw``, a Zarr (v2 or v3) or OME-Zarr store (a folder),
        an HDF5 file ``.h5``/``.hdf5``/``.hdf``, an MRC/CCP4 map, or a FITS cube (``.fits``, ``.fit``, ``.fts``,
        ``.fits.gz``, ``.fz``: north up, east left seen from +x, in pixels; docs/coordinates.md §1), or a post-stack
        SEG-Y cube (``.sgy``, ``.segy``, through segyio: time down, inlines along x).
        ``file.h5:/name`` and ``store.zarr:/name`` name an array inside; without a name the store's only
        3-D/4-D array is read (an OME-Zarr image: its ``level``).
    shape : tuple of int, optional
        ``.raw`` only: ``(Z, Y, X)`` or ``(Z, Y, X, C)``, C-ordered (x fastest).
    dtype : str or numpy.dtype, optional
        ``.raw``: the sample type, e.g. ``"uint16"``; an MRC map of bytes (mode 0): ``"uint8"`` or ``"int8"``, how its
        bytes are read (MRC2014's are signed, IMOD's stamp may say unsigned; a signed reading that looks wrapped is
        warned of).
    spacing : float or 3 floats, optional
        Voxel size ``(dz, dy, dx)``; overrides the file's spacing, in the file's unit where it has one (``unit=``
        names another), along the array's axes as stored (before ``orientation=`` turns them); a FITS cube's along
        its axes as loaded (Dec, RA, spectral: ``(1, 1, 0.25)`` flattens the spectral axis four times).
    byte_order : {'<', '>'}, optional
        ``.raw`` only: little or big endian (default: this machine's).
    series : int or str, optional
        DICOM only: the series to load where the input holds several image series, as
        their listing shows it: its SeriesNumber, description (case aside) or
        ``SeriesInstanceUID``; of a CD of several studies ``"STUDY/SERIES"``, the study by its place as the listing
        heads it (``"1/2"``), or its date, accession number, StudyID, description or UID; a value that
        names several is refused, naming them.
    level : int, optional
        OME-Zarr only: the resolution level (default 0, the finest).
    frame : int, optional
        A time series only (a 4-D NIfTI, an MGH file of several frames, an ImageJ hyperstack or OME-TIFF with a T axis,
        an OME-Zarr image with a t axis, a FITS cube with several planes along a 4th axis, Stokes I/Q/U/V): the 0-based
        time point (plane) to read, negative from the end as Python counts; only its samples are read, and it is
        placed as a 3-D file of that one volume is.  A series read without it is refused, naming how many there are.
    chunks : None, False, "auto" or int
        ``None``: Zarr and HDF5 are read chunk by chunk, ``.npy``, ``.raw``, ``.nii``, ``.mgh``, MRC, FITS,
        TIFF and folders of TIFF slices too when their volume takes at least
        ``CHUNKED_MIN_BYTES`` (1 GiB) as float32; everything else is read whole.  ``False``: read whole.
        ``"auto"``: chunk by chunk, chunks of at most ``CHUNK_BYTES`` in multiples
        of the store's own.  An int: chunk by chunk, cubes of that edge in voxels.
        Chunked volumes hold a Dask array, read only when computed (docs/chunked.md).
    nan : float, optional
        The value of NaN voxels, in the file's units: "no data" (FSL and SPM write NaN outside their masks),
        replaced before anything else.  Without it a volume holding NaN is refused.
    subtract : float
        Subtracted from every voxel (after ``hu_to_mu``), so that the data is ~0
        outside the object; kept as the volume's ``subtracted``, so transfer functions
        stay in the input's units (HU for CT, attenuation with ``hu_to_mu``).
    hu_to_mu : bool
        Convert CT Hounsfield units to linear attenuation
        ``mu = mu_water * (1 + HU / 1000)``, clipped at 0 (air -> 0).
    mu_water : float
        Attenuation of water per world unit (default 0.0193 per mm, ~60 keV).
    progress_bar : bool, optional
        Show a bar while reading slices; None shows it when stderr is a terminal.
    orientation : str, optional
        An input that carries no orientation (``.npy``, ``.raw``, TIFF, a folder of slices, Zarr, HDF5, MRC): the
        directions its x, y and z index axes (array axes 2, 1, 0, as stored) point to, as three of nibabel's axis
        codes (``"LPS"``: x to the patient's left, y posterior, z superior; what ``nibabel.aff2axcodes`` says of a
        NIfTI's (x, y, z) axes); the volume is turned into RAS+ as a medical file is (docs/coordinates.md §1).
        Refused for NIfTI, MGH, NRRD, DICOM, FITS and SEG-Y, which carry their own.
    unit : str, optional
        The world unit, the length of the spacing's 1 (:data:`clwave.io.images.UNIT_METRES`: "mm", "um"...);
        default the file's (:func:`world_unit`; None where it gives none).
    origin : 3 floats, optional
        World position ``(x, y, z)`` of the volume's centre, after ``orientation=``; default the file's, else 0.
    labels : bool, optional
        Whether the volume is a label map (a segmentation, :attr:`Volume.labels`), where you know better than the
        guess: by default a NIfTI's intent ``NIFTI_INTENT_LABEL``, else its values as stored
        (:func:`~clwave.model.labels.looks_like_labels`; a chunked volume's are not looked at) (docs/model.md §5).
    fits : callable, optional
        ``fits(voxels, channels)``, called with the size the file's header declares before a volume read whole
        (not chunk by chunk) is read (a stack of slices: once its first slice is read), to refuse one that is too
        big by raising a :class:`~clwave.errors.ClwaveError` (the command line weighs the model it makes).
        Whatever ``fits`` says, a volume whose reading would not fit in the memory available is refused then
        (``HostMemoryError``).

    Returns
    -------
    Volume

    Raises
    ------
    FileFormatError
        Missing, unknown, truncated or corrupt input.
    InputError
        Bad arguments (``frame=`` out of range, or for an input of one volume), several DICOM series without
        ``series=``, or data that is not a volume (see :class:`Volume`).
    clwave.device.memory.HostMemoryError
        A volume read whole that would not fit in memory (a ``MemoryError``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "v.npy"
    >>> np.save(f, np.zeros((4, 5, 6), np.int16))
    >>> load(f, spacing=(2.0, 1.0, 1.0))
    Volume(shape=(4, 5, 6), channels=1, spacing=(2.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))
    """
    if not file_name(path):  # Path("") is ".": the current folder was read as a folder of slices
        raise InputError("path '' names no file or folder; give the volume's",
                         cli="the input '' names no file or folder; give the volume's")
    path = Path(path)
    subtract = float32_number(subtract, "subtract")
    nan = None if nan is None else float32_number(nan, "nan")
    mu_water = finite_number(mu_water, "mu_water")
    labels = None if labels is None else flag(labels, "labels")
    if hu_to_mu and mu_water <= 0:
        raise InputError(f"mu_water={mu_water} must be positive (attenuation of water per "
                         "world unit)")
    path, inner = _split_inner(path)
    kind = _kind(path)
    frame = check_frame(frame)
    _reject_unused(kind, shape=shape, dtype=dtype, byte_order=byte_order, series=series, level=level, frame=frame)
    turn = check_orientation(kind, orientation)
    chunks = check_chunks(chunks, kind, path)

    with reading(path):
        data, file_spacing, file_origin, obliquity, modality = _read(kind, path, inner, shape, dtype, byte_order,
                                                                     series, level, chunks, progress_bar, fits,
                                                                     spacing is None, frame)
    if not is_dask(data):
        data = np.asarray(data)
    if labels is None:  # a label map: told by a NIfTI's intent, or by its values as stored (integers, before float32)
        labels = (kind == "nifti" and nifti.label_intent(path)) or (not is_dask(data) and looks_like_labels(data))
    stored = data.dtype
    photo = data.ndim == 4 and stored.kind in "iu" and _photo(kind, path)
    if data.dtype.kind in "biuf":  # anything else: Volume explains the dtype problem
        if hu_to_mu and data.ndim != 3:
            channels = f"scalar CT volumes, but this one has {data.shape[3]} channels"
            raise InputError(f"hu_to_mu converts {channels}; leave hu_to_mu off",
                             cli=f"--hu-to-mu converts {channels}; leave --hu-to-mu out")
        convert = partial(to_float32, path=path, mu_water=mu_water if hu_to_mu else None, subtract=subtract,
                          nan=nan)
        data = data.map_blocks(convert, dtype=np.float32) if is_dask(data) else convert(data, copy=False)
    placed = origin if origin is not None else file_origin if file_origin is not None else (0.0, 0.0, 0.0)
    provenance = dict(file=str(path) + (f":/{inner}" if inner else ""), frame=frame)
    if hu_to_mu and modality is not None:  # attenuation now, not the series' units
        modality = dict(modality, units=None)
    if turn is not None and origin is None:  # the file's origin turned with its axes; origin= is RAS already
        placed = tuple(turn[:, ::-1] @ np.asarray(placed, float))
    return Volume(data, spacing=spacing if spacing is not None else (file_spacing or 1.0), origin=placed,
                  subtracted=subtract, obliquity=obliquity, labels=labels, stored_dtype=stored, photo=photo,
                  unit=unit if unit is not None else _world_unit(kind, path, inner), provenance=provenance,
                  modality=modality, orientation=orientation)


def check_orientation(kind, orientation):
    """The turn into RAS+ (:func:`.geometry.axis_turn`) of ``orientation=`` (None without it), refused in one line for
    an input whose header places it in RAS+ (:data:`RAS_FORMATS`), on the sky (FITS) or time down (SEG-Y)."""
    if orientation is None:
        return None
    if kind in RAS_FORMATS + ("fits", "segy"):
        placed = dict(fits="on the sky, north up and east left,", segy="time (or depth) down, inlines along x,")
        placed = placed.get(kind, "in RAS+")
        raise InputError(f"orientation= is for inputs that carry none (.npy, .raw, TIFF, folders of slices, Zarr, "
                         f"HDF5, MRC); a {kind} input is put {placed} by its own header: leave it out",
                         cli=f"--orientation is for inputs that carry none (.npy, .raw, TIFF, folders of slices, "
                             f"Zarr, HDF5, MRC); a {kind} input is put {placed} by its own header: leave it out")
    return axis_turn(orientation)


def in_ras(path) -> bool:
    """Whether :func:`load` places the input at ``path`` in RAS+ by its own header (:data:`RAS_FORMATS`: a patient's
    axes); False where its format cannot be told (a file no longer there)."""
    try:
        return _kind(_split_inner(path)[0]) in RAS_FORMATS
    except (ClwaveError, OSError):
        return False


def _photo(kind, path) -> bool:
    """Whether the colour samples of a ``kind`` input are a photo's, straight colour and alpha (:attr:`Volume.photo`):
    PNG and JPEG slices, and TIFF colour samples (RGB, RGBA), not an OME-TIFF's channels."""
    if kind in ("png-folder", "jpeg-folder"):
        return True
    if kind in ("tiff", "tiff-folder"):
        with reading(path):
            return tiff.colour_samples(path if kind == "tiff" else slices.slice_files(path)[1][0])
    return False


def _read(kind, path, inner, shape, dtype, byte_order, series, level, chunks, progress_bar, fits, warn_spacing,
          frame=None):
    """``(data, spacing or None, origin or None, obliquity, modality)`` of a ``kind`` input as its loader reads it
    (not yet float32; of a time series its time point ``frame``); the obliquity (degrees off the scanner's axes,
    :func:`.shared.to_canonical`) is 0 but for medical formats, the modality (:attr:`Volume.modality`) None but for
    DICOM."""
    if kind == "dicom-frames":
        return dicom_frames.read_dicom_frames([path], fits)
    if kind == "dicom":
        return dicom_tree.read_dicom(path, series, progress_bar, fits)
    return (*_read_placed(kind, path, inner, shape, dtype, byte_order, level, chunks, progress_bar, fits,
                          warn_spacing, frame), None)


def _read_placed(kind, path, inner, shape, dtype, byte_order, level, chunks, progress_bar, fits, warn_spacing, frame):
    """:func:`_read`'s first four of the formats other than DICOM."""
    if kind == "zarr":
        return (*zarr.read_zarr(path, inner, level, chunks, fits, frame), 0.0)
    if kind == "hdf5":
        return (*hdf5.read_hdf5(path, inner, chunks, fits), 0.0)
    if kind == "raw":
        return (*raw.read_raw(path, shape, dtype, byte_order, chunks, fits), 0.0)
    if kind == "npy":
        return raw.read_npy(path, chunks, fits), None, None, 0.0
    if kind == "nifti":
        return nifti.read_nifti(path, chunks, fits, frame)
    if kind == "mgh":
        return mgh.read_mgh(path, chunks, fits, frame)
    if kind == "mrc":
        return (*mrc.read_mrc(path, chunks, fits, warn_spacing, dtype), 0.0)
    if kind == "nrrd":
        return nrrd.read_nrrd(path, fits, warn_spacing)
    if kind == "segy":
        return (*segy.read_segy(path, fits, warn_spacing), 0.0)
    if kind == "fits":
        return (*fits_cube.read_fits(path, chunks, fits, frame), 0.0)
    if kind == "tiff":
        return (*tiff.read_tiff(path, fits, chunks=chunks, warn_spacing=warn_spacing, frame=frame), 0.0)
    return slices.read_slice_folder(path, progress_bar, fits, chunks, warn_spacing), None, None, 0.0


#: The keys of :func:`describe`'s facts, the same for every format: a fact the header does not give is None
def world_unit(path) -> str | None:
    """The world unit of a volume file where it is a length its header gives (:data:`clwave.io.images.UNIT_METRES`):
    DICOM's and MGH's millimetres, a NIfTI's or NRRD's own, an OME-TIFF's micrometres, an ImageJ stack's or an
    OME-Zarr image's unit or an MRC map's ångströms; None for the others (voxel units, or units clwave does not
    read)."""
    path, inner = _split_inner(Path(path))
    return _world_unit(_kind(path), path, inner)


def _world_unit(kind, path, inner):
    if kind in ("nifti", "nrrd", "tiff", "mrc", "zarr", "segy"):
        with reading(path):
            if kind == "zarr":
                return zarr.world_unit(path, inner)
            return dict(nifti=nifti, nrrd=nrrd, tiff=tiff, mrc=mrc, segy=segy)[kind].world_unit(path)
    return "mm" if kind in ("dicom", "dicom-frames", "mgh") else None


DESCRIBED = ("file", "format", "bytes", "shape", "channels", "dtype", "stored_shape", "stored_dtype", "resampled",
             "spacing", "origin", "spacing_in_file", "obliquity", "time", "refused", "rescale", "padding", "nifti",
             "fits", "segy", "series")


def describe(path, *, series=None, level=None, frame=None, shape=None, dtype=None, byte_order=None) -> dict:
    """What :func:`load` reads of a volume file (or folder) before its voxels (``clwave info FILE``), with the keys
    :data:`DESCRIBED` whatever the format (None: a fact the header does not give, or not before the voxels):

    ``file``, ``format``, ``bytes`` on disk; ``shape`` (z, y, x[, c]) as ``load`` gives it, ``channels``, and the
    ``dtype`` of the samples as read; a format read whole (NRRD, TIFF, DICOM, ``.nii.gz``, a sheared NIfTI, a time
    series) the ``stored_shape`` its loader weighs before reading, before it orders the axes (a DICOM series: its
    slices, rows and columns, rescaled to float32; a time series: time axis included), and whether that is a
    resampling of the stored samples (``resampled``: a gantry tilt's straight stack, a sheared NIfTI's straight
    grid, wider by the shifts); ``spacing`` (dz, dy, dx), ``origin`` (x, y, z) and ``obliquity`` as ``load`` gives
    them, where the header places the volume (NRRD and plain TIFFs: their loaders find them with the voxels), and
    ``spacing_in_file``; a time series its ``time`` (``points``, ``step`` and ``unit``: None where the header gives
    none, or no positive finite step; ``along``: "time", or a FITS cube's axis, "STOKES"; ``frame``: the one
    ``frame=`` picks, as ``load`` checks it, else None) and without ``frame=`` ``refused`` (the one line ``load``
    refuses it with); ``frame=`` of an input of one volume is refused as ``load`` refuses it; a DICOM series its
    ``stored_dtype``, ``rescale`` (each distinct ``[slope, intercept]``) and ``padding`` (stored values, [] where
    none); a NIfTI file ``nifti`` (:func:`.nifti.header_facts`).  A ``.raw`` file has no
    header: described by its ``shape`` and ``dtype`` (and ``byte_order``) as :func:`load` takes them, refused
    (:class:`FileFormatError`) without them."""
    path, inner = _split_inner(Path(path))
    kind = _kind(path)
    if kind == "raw" and (shape is None or dtype is None):
        raise FileFormatError(f"{path} is a .raw file: it has no header (its shape and type are given to read it, "
                              f"shape= and dtype=)", cli=f"{path} is a .raw file: it has no header (its shape and type "
                                                         f"are given to read it, --shape and --dtype)")
    frame = check_frame(frame)
    _reject_unused(kind, shape=shape, dtype=dtype, byte_order=byte_order, series=series, level=level, frame=frame)
    # a Dask array over the file: nothing read until computed; a TIFF is described as its whole read weighs it (the
    # axes as stored, before the loader orders them)
    lazy = check_chunks(None, kind, path) is not False and kind not in ("tiff", "tiff-folder")
    size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) if path.is_dir() else path.stat().st_size
    facts = dict.fromkeys(DESCRIBED)
    facts.update(file=str(path) + (f":/{inner}" if inner else ""), format=kind, bytes=size, resampled=False)
    def read(k):  # a lazy read never weighs (nothing is read until computed) unless it must read whole (sheared)
        return _read(kind, path, inner, shape, dtype, byte_order, series, level, "auto" if lazy else False, False,
                     _declared, False, k)

    with reading(path):
        try:
            try:
                data, spacing, origin, obliquity, _ = read(None)
                one_volume(frame, facts["file"])  # an input of one volume: frame= refused as load refuses it
            except Declared:
                one_volume(frame, facts["file"])
                raise
            except TimeSeries as points:
                if frame is None:
                    raise
                picked = points.pick(frame, facts["file"])
                facts.update(time=dict(points=points.points, step=points.step, unit=points.unit, along=points.along,
                                       frame=picked))
                data, spacing, origin, obliquity, _ = read(picked)  # that volume, as load reads it
        except (Declared, TimeSeries) as declared:
            facts.update(_header_facts(kind, path))  # the header as the read has checked it
            channels = declared.channels
            facts.update(stored_shape=list(declared.shape), dtype=str(declared.dtype), channels=channels)
            if isinstance(declared, Declared):
                facts.update(resampled=declared.resampled, **declared.facts)
            else:
                facts.update(time=dict(points=declared.points, step=declared.step, unit=declared.unit,
                                       along=declared.along, frame=None), refused=str(declared))
            if declared.loaded is not None:
                facts["shape"] = list(declared.loaded) + [channels] * (channels > 1)
            if declared.placed is not None:
                spacing, origin, obliquity = declared.placed
                check_placement(declared.loaded, spacing, origin)  # as the read's Volume refuses it
                facts.update(spacing=[float(s) for s in spacing], origin=[float(o) for o in origin],
                             obliquity=obliquity, spacing_in_file=True)
            elif kind in _SLICE_FOLDERS:  # stacked as stored, and no file places them: load's unit spacing
                facts.update(shape=list(declared.shape), spacing=[1.0] * 3, origin=[0.0] * 3, obliquity=0.0,
                             spacing_in_file=False)
            return facts
        facts.update(_header_facts(kind, path))
    volume = Volume(data, spacing=spacing or 1.0, origin=origin if origin is not None else (0.0, 0.0, 0.0))
    return dict(facts, shape=list(data.shape), dtype=str(data.dtype), channels=volume.channels,
                spacing=list(volume.spacing), origin=list(volume.origin), spacing_in_file=spacing is not None,
                obliquity=obliquity)


def _header_facts(kind, path) -> dict:
    """What a format's header says beyond the volume's place (a NIfTI's codes, orientation, shear and scaling)."""
    facts = dict(nifti=nifti, fits=fits_cube, segy=segy)
    return facts[kind].header_facts(path) if kind in facts else {}


def _declared(voxels, channels):
    raise Declared()


def _split_inner(path):
    """``(file, name inside it or None)`` of ``file.h5:/name`` or ``store.zarr:/name`` (an existing path is
    never split)."""
    text = os.fspath(path)
    match = _INNER_PATH.fullmatch(text)
    if match and not os.path.exists(text):
        return Path(match[1]), match[2].strip("/") or None
    return Path(text), None


def _kind(path: Path) -> str:
    """Format of ``path`` from its extension, or the content of a folder."""
    from pydicom.uid import MediaStorageDirectoryStorage

    zarr_named = path.suffix.lower() == ".zarr"
    if path.is_dir():
        if any((path / name).is_file() for name in zarr.ZARR_METADATA):
            return "zarr"
        if zarr_named:
            raise FileFormatError(f"{path} is not a Zarr store: it has no {', '.join(zarr.ZARR_METADATA)}; name the "
                                  "store's top folder (or one array or group folder inside it)")
        slice_format, files = slices.slice_files(path)
        if slice_format in ("PNG", "JPEG") and _holds_dicom(path, files):  # a series with its previews
            return "dicom"
        return f"{slice_format.lower()}-folder" if slice_format else "dicom"
    name = path.name.lower()
    suffix = next((s for s in (".nii.gz",) + fits_cube.FITS_SUFFIXES if name.endswith(s)), path.suffix.lower())
    if not path.exists():
        raise FileFormatError(f"no file or folder at {path}; supported inputs: {SUPPORTED}")
    if not path.is_file():  # a reader of a FIFO waits for a writer, of a device for ever
        raise not_a_file(path)
    if zarr_named:
        raise FileFormatError(f"{path} is a file, not a Zarr store; clwave reads Zarr stores that are folders "
                              "(unzip a zipped store first)")
    if suffix in (".dcm", ".ima") or suffix not in _FILE_KINDS and _is_dicom(path):  # IM0001, 1.2.840....
        with reading(path):
            header = dicom.dcmread(path, defer_size=1024)  # its PixelData noted, not read
        if header.file_meta.get("MediaStorageSOPClassUID") == MediaStorageDirectoryStorage:
            return "dicom"  # a DICOMDIR: the series it lists
        if int(header.get("NumberOfFrames") or 1) > 1:
            return "dicom-frames"
        raise FileFormatError(dicom_tree.describe_file(path, header) or f"{path} is one DICOM slice; pass the folder "
                              f"that holds the whole series ({path.parent})")
    image = next((kind for kind in ("PNG", "JPEG") if suffix in slices.SLICE_SUFFIXES[kind]), None)
    if image:  # a photo stack's slice, as Fiji's Image Sequence takes one
        raise FileFormatError(f"{path} is one {image} image; clwave reads a folder of {image} slices as a stack: give "
                              f"its folder ({path.parent})")
    if suffix not in _FILE_KINDS:
        raise FileFormatError(f"unknown file type {suffix or '(no extension)'!r} of {path}; "
                              f"supported inputs: {SUPPORTED}")
    return _FILE_KINDS[suffix]


def _holds_dicom(folder, images, looked_at=3) -> bool:
    """Whether a folder of PNG or JPEG files holds DICOM files too (a series exported with its previews), by the
    first few of its other files."""
    images = set(images)
    others = [p for p in folder_files(folder) if p not in images][:looked_at]
    return any(p.suffix.lower() in (".dcm", ".ima") or _is_dicom(p) for p in others)


def _is_dicom(path) -> bool:
    """Whether ``path`` begins as a DICOM file does (a preamble, then "DICM"): DICOM files often have no extension."""
    from pydicom.misc import is_dicom

    with reading(path):
        return is_dicom(path)


def _reject_unused(kind, **options):
    """Refuse options the format ignores, so a mistaken call is not silently accepted."""
    given = [name for name, value in options.items() if value is not None and kind not in _ONLY_FOR[name][0]]
    given = [name for name in given if _ONLY_FOR[name] == _ONLY_FOR[given[0]]]  # those of the first's kinds
    if given:
        needs, one = _ONLY_FOR[given[0]][1], len(given) == 1
        verb, them = ("applies", "it") if one else ("apply", "them")
        raise InputError(f"{'=, '.join(given)}= only {verb} to {needs}; leave {them} out for a {kind} input",
                         cli=f"{', '.join('--' + n.replace('_', '-') for n in given)} only {verb} to {needs}; "
                             f"leave {them} out for a {kind} input")
