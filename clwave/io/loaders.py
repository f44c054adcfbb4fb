"""Read volumes from files: one :func:`load` for every supported format.

The result is a (z, y, x[, c]) float32 :class:`~clwave.model.volume.Volume`; medical formats
(NIfTI, NRRD, DICOM) are put in the canonical RAS+ orientation with spacing and origin in scanner
millimetres, the others keep their array axes (docs/coordinates.md §1).  Zarr, OME-Zarr and HDF5
stores, and large .npy, .raw and .nii files, are read chunk by chunk as Dask arrays (docs/chunked.md §1).
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections import defaultdict
from contextlib import contextmanager
from fractions import Fraction
from functools import partial
from pathlib import Path

import numpy as np

from ..errors import ClwaveError, FileFormatError, InputError, finite_number
from .progress import progress
from ..model.volume import Volume, is_dask

log = logging.getLogger(__name__)

SUPPORTED = (".npy, .nii, .nii.gz, .nrrd, .nhdr, .tif/.tiff (multi-page, or a folder of "
             "2-D slices), a folder of DICOM files, .raw (with shape= and dtype=), a Zarr or OME-Zarr "
             "store (folder), .h5/.hdf5 (file.h5:/dataset)")

#: chunks=None reads .npy, .raw and .nii files whose volume takes at least this many bytes as float32 chunk
#: by chunk (Zarr and HDF5 always), smaller ones whole (docs/chunked.md §1).
CHUNKED_MIN_BYTES = 1 << 30
#: chunks="auto": at most this many bytes of float32 per chunk, in multiples of the store's own chunks
#: (of 64 voxels per axis for files without chunks: 128³ voxels), or the store's own when they are bigger.
#: Small, because the chunked transform holds some ten times a block a thread, and a slab of blocks for
#: their halos (docs/chunked.md §2, §5).
CHUNK_BYTES = 8 << 20
#: More chunks than this make Dask's task graph itself too big to handle.
MAX_CHUNKS = 100_000

_TIFF_SUFFIXES = (".tif", ".tiff")
_FILE_KINDS = {".npy": "npy", ".nii": "nifti", ".nii.gz": "nifti", ".nrrd": "nrrd",
               ".nhdr": "nrrd", ".tif": "tiff", ".tiff": "tiff", ".raw": "raw",
               ".h5": "hdf5", ".hdf5": "hdf5", ".hdf": "hdf5"}
# The formats read chunk by chunk (not .nii.gz: gzip cannot seek)
_CHUNKABLE = ("zarr", "hdf5", "npy", "raw", "nifti")
_ZARR_METADATA = ("zarr.json", ".zarray", ".zgroup")  # v3, v2 array, v2 group
# 'file.h5:/path/in/file' or 'store.zarr:/path': the last ':' after such a suffix
_INNER_PATH = re.compile(r"(.*\.(?:h5|hdf5|hdf|zarr)):(.*)", re.IGNORECASE | re.DOTALL)
# Options that apply to one kind of input only
_ONLY_FOR = {"shape": ".raw files", "dtype": ".raw files", "byte_order": ".raw files", "series": "DICOM folders",
             "level": "OME-Zarr images"}

# Sign of each world axis when converting to RAS; LPS is DICOM's patient space.
_LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
_NRRD_SPACE_SIGNS = {
    "right-anterior-superior": (1, 1, 1), "ras": (1, 1, 1),
    "left-anterior-superior": (-1, 1, 1), "las": (-1, 1, 1),
    "left-posterior-superior": (-1, -1, 1), "lps": (-1, -1, 1),
}
# Attributes every slice of a DICOM image series needs
_DICOM_SLICE_TAGS = ("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing",
                     "Rows", "Columns", "PixelData")


def load(path, *, shape=None, dtype=None, spacing=None, byte_order=None, series=None, level=None,
         chunks=None, background=0.0, hu_to_mu=False, mu_water=0.0193, progress_bar=None) -> Volume:
    """Load a volume file or folder as a :class:`Volume` (RAS+ for medical data).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy``, ``.nii``, ``.nii.gz``, ``.nrrd``, ``.nhdr``, a multi-page
        ``.tif``/``.tiff``, a folder of 2-D TIFF slices (stacked in natural name
        order: ``slice2`` before ``slice10``), a folder of DICOM files (other files
        in it are ignored), ``.raw``, a Zarr (v2 or v3) or OME-Zarr store (a folder),
        or an HDF5 file ``.h5``/``.hdf5``/``.hdf``.  ``file.h5:/name`` and
        ``store.zarr:/name`` name an array inside; without a name the store's only
        3-D/4-D array is read (an OME-Zarr image: its ``level``).
    shape : tuple of int, optional
        ``.raw`` only: ``(Z, Y, X)`` or ``(Z, Y, X, C)``, C-ordered (x fastest).
    dtype : str or numpy.dtype, optional
        ``.raw`` only: the sample type, e.g. ``"uint16"``.
    spacing : float or 3 floats, optional
        Voxel size ``(dz, dy, dx)``; overrides the file's spacing.
    byte_order : {'<', '>'}, optional
        ``.raw`` only: little or big endian (default: this machine's).
    series : int or str, optional
        DICOM only: 0-based index or ``SeriesInstanceUID`` of the series to load
        when the folder holds several.
    level : int, optional
        OME-Zarr only: the resolution level (default 0, the finest).
    chunks : None, False, "auto" or int
        ``None``: Zarr and HDF5 are read chunk by chunk, ``.npy``, ``.raw`` and
        ``.nii`` too when their volume takes at least ``CHUNKED_MIN_BYTES`` (1 GiB)
        as float32; everything else is read whole.  ``False``: read whole.
        ``"auto"``: chunk by chunk, chunks of at most ``CHUNK_BYTES`` in multiples
        of the store's own.  An int: chunk by chunk, cubes of that edge in voxels.
        Chunked volumes hold a Dask array, read only when computed (docs/chunked.md).
    background : float
        Subtracted from every voxel (after ``hu_to_mu``), so that the data is ~0
        outside the object.
    hu_to_mu : bool
        Convert CT Hounsfield units to linear attenuation
        ``mu = mu_water * (1 + HU / 1000)``, clipped at 0 (air -> 0).
    mu_water : float
        Attenuation of water per world unit (default 0.0193 per mm, ~60 keV).
    progress_bar : bool, optional
        Show a bar while reading slices; None shows it when stderr is a terminal.

    Returns
    -------
    Volume

    Raises
    ------
    FileFormatError
        Missing, unknown, truncated or corrupt input.
    InputError
        Bad arguments, several DICOM series without ``series=``, or data that is
        not a volume (see :class:`Volume`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "v.npy"
    >>> np.save(f, np.zeros((4, 5, 6), np.int16))
    >>> load(f, spacing=(2.0, 1.0, 1.0))
    Volume(shape=(4, 5, 6), channels=1, spacing=(2.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"path must be a file or folder name (str or pathlib.Path), got {type(path).__name__}")
    path = Path(path)
    background = finite_number(background, "background")
    mu_water = finite_number(mu_water, "mu_water")
    if hu_to_mu and mu_water <= 0:
        raise InputError(f"mu_water={mu_water} must be positive (attenuation of water per "
                         "world unit)")
    path, inner = _split_inner(path)
    kind = _kind(path)
    if kind != "raw":
        _reject_unused(kind, shape=shape, dtype=dtype, byte_order=byte_order)
    if kind != "dicom":
        _reject_unused(kind, series=series)
    if kind != "zarr":
        _reject_unused(kind, level=level)
    chunks = _check_chunks(chunks, kind, path)

    with _reading(path):
        if kind == "zarr":
            data, file_spacing, origin = _read_zarr(path, inner, level, chunks)
        elif kind == "hdf5":
            data, file_spacing, origin = _read_hdf5(path, inner, chunks)
        elif kind == "raw":
            data, file_spacing, origin = _read_raw(path, shape, dtype, byte_order, chunks)
        elif kind == "npy":
            data, file_spacing, origin = _read_npy(path, chunks), None, None
        elif kind == "nifti":
            data, file_spacing, origin = _read_nifti(path, chunks)
        elif kind == "nrrd":
            data, file_spacing, origin = _read_nrrd(path)
        elif kind == "tiff":
            data, file_spacing, origin = _read_tiff(path), None, None
        elif kind == "tiff-folder":
            data, file_spacing, origin = _read_tiff_folder(path, progress_bar), None, None
        else:
            data, file_spacing, origin = _read_dicom_folder(path, series, progress_bar)

    if not is_dask(data):
        data = np.asarray(data)
    if data.dtype.kind in "biuf":  # anything else: Volume explains the dtype problem
        if hu_to_mu and data.ndim != 3:
            raise InputError(f"hu_to_mu converts scalar CT volumes, but this one has "
                             f"{data.shape[3]} channels; leave hu_to_mu off")
        convert = partial(_to_float32, path=path, mu_water=mu_water if hu_to_mu else None, background=background)
        data = data.map_blocks(convert, dtype=np.float32) if is_dask(data) else convert(data, copy=False)
    return Volume(data,
                  spacing=spacing if spacing is not None else (file_spacing or 1.0),
                  origin=origin if origin is not None else (0.0, 0.0, 0.0))


# --------------------------------------------------------------------------- shared steps

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
    zarr_named = path.suffix.lower() == ".zarr"
    if path.is_dir():
        if any((path / name).is_file() for name in _ZARR_METADATA):
            return "zarr"
        if zarr_named:
            raise FileFormatError(f"{path} is not a Zarr store: it has no {', '.join(_ZARR_METADATA)}; name the "
                                  "store's top folder (or one array or group folder inside it)")
        return "tiff-folder" if _tiff_files(path) else "dicom"
    name = path.name.lower()
    suffix = ".nii.gz" if name.endswith(".nii.gz") else path.suffix.lower()
    if not path.exists():
        raise FileFormatError(f"no file or folder at {path}; supported inputs: {SUPPORTED}")
    if zarr_named:
        raise FileFormatError(f"{path} is a file, not a Zarr store; clwave reads Zarr stores that are folders "
                              "(unzip a zipped store first)")
    if suffix in (".dcm", ".ima"):
        raise FileFormatError(f"{path} is one DICOM slice; pass the folder that holds the whole series "
                              f"({path.parent})")
    if suffix not in _FILE_KINDS:
        raise FileFormatError(f"unknown file type {suffix or '(no extension)'!r} of {path}; "
                              f"supported inputs: {SUPPORTED}")
    return _FILE_KINDS[suffix]


def _reject_unused(kind, **options):
    """Refuse options the format ignores, so a mistaken call is not silently accepted."""
    given = [name for name, value in options.items() if value is not None]
    if given:
        needs = _ONLY_FOR[given[0]]
        raise InputError(f"{'=, '.join(given)}= only apply to {needs}; leave them out for a {kind} input",
                         cli=f"{', '.join('--' + n.replace('_', '-') for n in given)} only apply to {needs}; "
                             f"leave them out for a {kind} input")


@contextmanager
def _reading(path):
    """Turn any library exception while reading ``path`` into a one-line FileFormatError; the readers'
    own log lines (tifffile's on a cut file) are kept quiet, the error says what went wrong."""
    quiet = logging.getLogger("tifffile")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    try:
        yield
    except ClwaveError:
        raise
    except OSError as exc:
        if exc.errno is None:  # e.g. gzip.BadGzipFile, not a system error
            raise FileFormatError(_corrupt(path, exc)) from exc
        # exc.filename: e.g. the data file that a .nhdr header points to
        raise FileFormatError(f"cannot read {exc.filename or path}: {exc.strerror}; check the "
                              "path and its permissions") from exc
    except Exception as exc:
        raise FileFormatError(_corrupt(path, exc)) from exc
    finally:
        quiet.setLevel(level)


def _corrupt(path, exc) -> str:
    lines = str(exc).strip().splitlines()
    reason = type(exc).__name__ + (f": {lines[0][:200]}" if lines else "")
    return f"cannot read {path}: {reason}; the file may be truncated or corrupt"


def _to_float32(block, path, mu_water, background, copy=True):
    """``block`` (the whole volume, or one chunk as it is read) as float32: Hounsfield units -> attenuation
    when ``mu_water`` is given (clipped at 0: air, -1000 HU, is exactly 0), minus ``background``; float64
    values beyond float32's range are refused.  ``copy``: never write into ``block`` (a Dask chunk)."""
    if block.dtype.kind == "f" and block.dtype.itemsize > 4 and block.size:
        top = float(np.nanmax(np.abs(np.where(np.isfinite(block), block, 0.0))))
        if top > float(np.finfo(np.float32).max):
            raise InputError(f"{path} holds values up to {top:.3g}, beyond float32's range (3.4e38); rescale "
                             f"the data first")
    data = np.array(block, np.float32, order="C") if copy else np.ascontiguousarray(block, np.float32)
    if mu_water is not None:
        data += 1000.0
        data *= np.float32(mu_water / 1000.0)
        np.maximum(data, 0.0, out=data)
    if background:
        data -= np.float32(background)
    return data


def _check_chunks(chunks, kind, path):
    """``chunks`` validated for a ``kind`` input: None (by size), False (whole), "auto" or a cube edge."""
    edge = isinstance(chunks, (int, np.integer)) and not isinstance(chunks, (bool, np.bool_)) and chunks >= 1
    if not (edge or chunks is None or chunks is False or chunks == "auto"):
        raise InputError(f"chunks={chunks!r} must be None, False, 'auto' or a chunk edge in voxels (an int >= 1)",
                         cli=f"--chunks {chunks} must be auto, off or a chunk edge in voxels (an int >= 1)")
    if kind not in _CHUNKABLE or path.name.lower().endswith(".gz"):
        if chunks not in (None, False):
            found = "a .nii.gz file (gzip cannot seek: gunzip it first)" if kind == "nifti" else f"a {kind} input"
            raise InputError(f"chunks= applies to Zarr, HDF5, .npy, .raw and .nii inputs, not to {found}; leave "
                             "it out to read the volume whole",
                             cli=f"--chunks applies to Zarr, HDF5, .npy, .raw and .nii inputs, not to {found}; "
                                 "leave it out to read the volume whole")
        return False
    return "auto" if chunks is None and kind in ("zarr", "hdf5") else chunks


class _OnDemand:
    """A read-only array in a file that ``read(index)`` opens anew for each read: a Dask graph over it holds no
    open file and pickles small (for process-based schedulers)."""

    def __init__(self, read, shape, dtype, chunks=None):
        self.read, self.shape, self.dtype, self.chunks = read, tuple(shape), np.dtype(dtype), chunks
        self.ndim = len(self.shape)

    def __getitem__(self, index):
        return self.read(index)


def _read_memmap(path, dtype, shape, offset, order, index):
    return np.array(np.memmap(path, dtype, "r", offset, shape, order)[index])


def _read_dataset(path, name, index):
    import h5py

    with h5py.File(path, "r") as fh:
        return fh[name][index]


def _array(source, chunks, roles=None):
    """``source`` (an array read on demand: ``shape``, ``dtype``, ``source[index]``, maybe the store's ``chunks``)
    read whole, or as a Dask array that reads each chunk when it is computed (docs/chunked.md §1).

    ``chunks``: False, None (whole below ``CHUNKED_MIN_BYTES`` as float32), "auto" or a cube edge.  ``roles``
    names each axis: 's' spatial (chunked), 't' time (one per chunk), 'c' channel (whole); default: 3
    spatial axes, then channels.
    """
    shape = tuple(int(n) for n in source.shape)
    roles = roles or "s" * min(len(shape), 3) + "c" * max(len(shape) - 3, 0)
    if chunks is None:
        chunks = "auto" if 4 * math.prod(shape) >= CHUNKED_MIN_BYTES else False
    if chunks is False:
        return np.asarray(source[...])
    import dask.array as da
    from dask.array.core import normalize_chunks

    own = getattr(source, "chunks", None) or tuple(64 if r == "s" else 1 for r in roles)
    edges = [chunks] * len(roles)
    if chunks == "auto" and 4 * math.prod(n for n, r in zip(own, roles) if r == "s") >= CHUNK_BYTES:
        edges = own  # the store's chunks are big already: one each (a Zarr chunk is decoded whole)
    edges = tuple({"t": 1, "c": -1}.get(r, edge) for r, edge in zip(roles, edges))
    blocks = normalize_chunks(edges, shape, limit=CHUNK_BYTES, dtype=np.float32, previous_chunks=own)
    count = math.prod(len(b) for b in blocks)
    if count > MAX_CHUNKS:
        problem = (f"cut the {' x '.join(map(str, shape))} volume into {count:,} chunks; more than {MAX_CHUNKS:,} "
                   "make Dask's task graph too big: give a bigger chunk edge")
        raise InputError(f"chunks={chunks!r} {problem}", cli=f"--chunks {chunks} {problem}")
    return da.from_array(source, chunks=blocks, meta=np.empty((0,) * len(shape), source.dtype))


def _listing(arrays, most=8) -> str:
    """'/a (5, 6, 7) int16, /b (4, 4) float32' for {name: array}, the first ``most`` of them."""
    names = list(arrays)
    text = ", ".join(f"/{n} {tuple(arrays[n].shape)} {arrays[n].dtype}" for n in names[:most])
    return (text + (f" and {len(names) - most} more" if len(names) > most else "")) or "none"


def _pick_array(arrays, name, store):
    """The array ``name`` of ``arrays`` ({name: array} of a Zarr or HDF5 store), or without a name its only
    3-D/4-D array."""
    if name is None:
        volumes = [n for n, a in arrays.items() if len(a.shape) in (3, 4)]
        if len(volumes) != 1:
            raise FileFormatError(f"{store} holds {len(volumes) or 'no'} 3-D/4-D arrays (its arrays: "
                                  f"{_listing(arrays)}); name one as {store}:/NAME")
        name = volumes[0]
    if name not in arrays:
        raise FileFormatError(f"{store} holds no array /{name}; its arrays: {_listing(arrays)}")
    array = arrays[name]
    if len(array.shape) not in (3, 4):
        raise FileFormatError(f"{store}:/{name} has shape {tuple(array.shape)}; clwave reads a 3-D (z, y, x) or "
                              f"4-D (z, y, x, c) array: name another one ({_listing(arrays)})")
    return name, array


def _to_canonical(array_ijk, affine_ras):
    """Reorient an array with an index -> RAS affine to ``(z, y, x)`` RAS+ axes.

    Parameters
    ----------
    array_ijk : ndarray or Dask array, shape (ni, nj, nk) or (ni, nj, nk, c)
        Voxels indexed like the affine's columns.
    affine_ras : ndarray, shape (4, 4)
        Maps ``(i, j, k, 1)`` to RAS world coordinates (mm).

    Returns
    -------
    array_zyx : ndarray or Dask array
        Permuted and flipped view: axis 0 -> superior, 1 -> anterior, 2 -> right.
    spacing_zyx : tuple of float
        ``(dz, dy, dx)``, the lengths of the reoriented affine's columns.
    origin_xyz : tuple of float
        RAS position of the volume centre.
    """
    from nibabel.affines import obliquity
    from nibabel.orientations import inv_ornt_aff, io_orientation

    ornt = io_orientation(affine_ras)
    # nibabel's apply_orientation by slicing and transposing, so a Dask array stays lazy
    flips = tuple(slice(None, None, -1) if flip < 0 else slice(None) for flip in ornt[:, 1])
    array_xyz = array_ijk[flips].transpose(tuple(np.argsort(ornt[:, 0])) + tuple(range(3, array_ijk.ndim)))
    affine_xyz = affine_ras @ inv_ornt_aff(ornt, array_ijk.shape[:3])
    tilt = np.degrees(np.abs(obliquity(affine_xyz)).max())
    if tilt > 0.01:
        log.warning("the volume is oblique by %.2f degrees; it is shown in the closest "
                    "canonical (RAS) orientation", tilt)
    spacing_xyz = np.linalg.norm(affine_xyz[:3, :3], axis=0)
    centre = affine_xyz @ np.append((np.array(array_xyz.shape[:3]) - 1) / 2, 1.0)
    array_zyx = array_xyz.transpose((2, 1, 0) + tuple(range(3, array_xyz.ndim)))
    return array_zyx, tuple(spacing_xyz[::-1]), tuple(centre[:3])


def _read_slices(paths, read_slice, desc, progress_bar):
    """Stack one 2-D slice per file along z, each read with its own error wrapping."""
    volume = None
    for z, path in enumerate(progress(paths, total=len(paths), desc=desc, enabled=progress_bar)):
        with _reading(path):
            image = read_slice(path)
        if volume is None:
            volume = np.empty((len(paths),) + image.shape, image.dtype)
        elif image.shape != volume.shape[1:]:
            raise FileFormatError(
                f"slice {path} has shape {image.shape} but {paths[0].name} has "
                f"{volume.shape[1:]}; all slices of a volume must have the same size")
        volume[z] = image
    return volume


def _natural_key(path):
    """Sort key where digit runs compare as numbers: slice2 < slice10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def _folder_files(folder):
    return sorted((p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")),
                  key=_natural_key)


def _tiff_files(folder):
    return [p for p in _folder_files(folder) if p.suffix.lower() in _TIFF_SUFFIXES]


# --------------------------------------------------------------------------- formats

def _read_raw(path, shape, dtype, byte_order, chunks):
    """Headerless samples, C order (x fastest); the file size must match exactly."""
    if shape is None or dtype is None:
        raise InputError(f"{path.name}: a .raw file has no header; give shape=(Z, Y, X) or "
                         "(Z, Y, X, C) and dtype= (e.g. 'uint16')")
    try:
        shape = tuple(int(n) for n in shape)
        dt = np.dtype(dtype)
    except (TypeError, ValueError):
        raise InputError(f"bad shape={shape!r} or dtype={dtype!r} for {path.name}; give "
                         "shape=(Z, Y, X) and a numpy dtype such as 'uint16'") from None
    if len(shape) not in (3, 4) or min(shape) < 1:
        raise InputError(f"shape={shape} must be (Z, Y, X) or (Z, Y, X, C) with positive sizes")
    if byte_order not in (None, "<", ">"):
        raise InputError(f"byte_order={byte_order!r} must be '<' (little endian) or '>' "
                         "(big endian)")
    if byte_order is not None:
        dt = dt.newbyteorder(byte_order)
    expected = int(np.prod(shape)) * dt.itemsize
    actual = os.path.getsize(path)
    if actual != expected:
        raise FileFormatError(
            f"{path} has {actual} bytes but shape {shape} of {dt.name} needs {expected} bytes; "
            "check shape= and dtype=, or the file is truncated")
    return _array(_OnDemand(partial(_read_memmap, str(path), dt, shape, 0, "C"), shape, dt), chunks), None, None


def _read_npy(path, chunks):
    """A .npy file, memory-mapped (C or Fortran order)."""
    mapped = np.load(path, mmap_mode="r", allow_pickle=False)  # reads the header only
    order = "F" if mapped.flags.f_contiguous and not mapped.flags.c_contiguous else "C"
    return _array(_OnDemand(partial(_read_memmap, str(path), mapped.dtype, mapped.shape, mapped.offset, order),
                            mapped.shape, mapped.dtype), chunks)


def _read_nifti(path, chunks):
    """NIfTI-1/2 through nibabel: RGB24/RGBA32 become channels; time series are refused."""
    import nibabel

    image = nibabel.load(path, mmap=False)
    _check_declared_size(path, int(image.header["vox_offset"]),
                         int(np.prod(image.shape)) * image.header.get_data_dtype().itemsize, image.shape)
    proxy = image.dataobj  # reads on demand, applying scl_slope / scl_inter
    if proxy.ndim > 3:
        # NIfTI keeps time on the 4th axis and vector components on the 5th
        if proxy.shape[3] != 1 or any(n != 1 for n in proxy.shape[5:]):
            raise FileFormatError(
                f"{path} holds a NIfTI image of shape {proxy.shape}; clwave reads one 3-D "
                "volume (vector components on the 5th axis become channels): extract one "
                "volume first, e.g. with nibabel.funcs.four_to_three")
        proxy = proxy.reshape(proxy.shape[:3] + proxy.shape[4:5])
    data = _array(proxy, chunks)
    if data.dtype.names:  # RGB24 / RGBA32 structured samples
        data = np.stack([data[name] for name in data.dtype.names], axis=-1)
    return _to_canonical(data, image.affine)


def _check_declared_size(path, offset, nbytes, shape, gzip=None):
    """Refuse a header that declares more data than the file holds, before anything is allocated
    (gzip, by default for a ``.gz`` name: its trailer's size of the uncompressed stream, modulo 2^32)."""
    path = Path(path)
    if gzip if gzip is not None else path.name.lower().endswith(".gz"):
        with open(path, "rb") as fh:
            fh.seek(-4, os.SEEK_END)
            present = int.from_bytes(fh.read(4), "little")
        lies = (offset + nbytes) % 2 ** 32 > present  # the trailer counts the stream modulo 2^32
    else:
        present = path.stat().st_size
        lies = offset + nbytes > present
    if lies:
        raise FileFormatError(f"{path}: its header declares {' x '.join(map(str, shape))} voxels ({nbytes:,} bytes) "
                              f"but the file holds {present:,} bytes; it is truncated or its header is wrong")


def _read_nrrd(path):
    """NRRD/NHDR through pynrrd: ``space directions`` and ``space`` give the RAS affine."""
    import nrrd

    _check_nrrd_size(path)
    data, header = nrrd.read(str(path))  # index_order 'F': axes in file order, fastest first
    directions = header.get("space directions")
    if directions is not None:
        directions = np.asarray(directions, float)
        spatial = [a for a in range(data.ndim) if np.all(np.isfinite(directions[a]))]
    elif "kinds" in header:
        spatial = [a for a, kind in enumerate(header["kinds"])
                   if kind.lower() in ("domain", "space")]
    else:
        spatial = list(range(data.ndim))
    others = [a for a in range(data.ndim) if a not in spatial]
    width = directions.shape[1] if directions is not None else 3
    if len(spatial) != 3 or len(others) > 1 or width != 3:
        raise FileFormatError(
            f"{path} has {data.ndim} axes of sizes {data.shape} in a {width}-D space; clwave "
            "reads 3 spatial axes in 3-D space plus at most one channel axis")
    data = np.moveaxis(data, others, list(range(3, data.ndim)))

    affine = np.eye(4)
    if directions is not None:
        affine[:3, :3] = directions[spatial].T
        affine[:3, 3] = header.get("space origin", np.zeros(3))
    else:
        spacings = np.asarray(header.get("spacings", np.ones(data.ndim)), float)[spatial]
        affine[:3, :3] = np.diag(np.where(np.isfinite(spacings), spacings, 1.0))
    # other spaces (scanner-xyz, 3D-right-handed, none) are taken as RAS
    signs = _NRRD_SPACE_SIGNS.get(str(header.get("space", "")).lower(), (1, 1, 1))
    return _to_canonical(data, np.diag(signs + (1,)) @ affine)


def _check_nrrd_size(path):
    """A NRRD header that declares more voxels than its raw or gzip data holds is refused before pynrrd
    allocates them (other encodings, and a missing detached data file, are left to pynrrd)."""
    import nrrd

    with open(path, "rb") as fh:
        header = nrrd.read_header(fh)
        offset = fh.tell()  # attached data start here
    encoding = str(header.get("encoding", "raw")).lower()
    if "data file" in header:  # a detached header: the data is a file of its own
        path, offset = Path(Path(path).parent, str(header["data file"])), 0
    if encoding not in ("raw", "gzip", "gz") or not Path(path).is_file():
        return
    if encoding != "raw":  # the gzip stream starts after the header; its trailer counts the stream alone
        offset = 0
    sizes = [int(n) for n in header["sizes"]]
    nbytes = int(np.prod(sizes, dtype=np.float64)) * nrrd.reader._determine_datatype(header).itemsize
    skip = max(int(header.get("byte skip", 0) or 0), 0)
    _check_declared_size(path, offset + skip, nbytes, sizes[::-1], gzip=encoding != "raw")


def _read_tiff(path):
    """A TIFF stack as ``(pages, y, x[, samples])``; one page gives one slice."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        data, axes = series.asarray(), series.axes
        if len(tif.pages) > 1 and len(axes.replace("S", "")) == 2:
            # pages written one at a time form one series each: stack them all
            data, axes = tif.asarray(key=range(len(tif.pages))), "Q" + axes
    if "S" in axes:  # samples per pixel (RGB/RGBA) go last, as channels
        data = np.moveaxis(data, axes.index("S"), -1)
        axes = axes.replace("S", "")
    if len(axes) > 3 or not axes.endswith("YX"):
        raise FileFormatError(
            f"{path} holds a TIFF series with axes {series.axes!r} and shape {series.shape}; "
            "clwave reads one stack of 2-D pages (axes like 'ZYX', optionally with RGB samples)")
    return data if len(axes) == 3 else data[np.newaxis]


def _read_tiff_folder(folder, progress_bar):
    """One 2-D TIFF per slice, stacked along z in natural name order."""
    def read_slice(path):
        pages = _read_tiff(path)
        if len(pages) != 1:
            raise FileFormatError(f"{path} holds {len(pages)} pages, but a folder of TIFF "
                                  "slices needs one 2-D image per file")
        return pages[0]

    return _read_slices(_tiff_files(folder), read_slice, "reading TIFF slices", progress_bar)


def _read_hdf5(path, name, chunks):
    """One dataset of an HDF5 file: the one named, or the file's only 3-D/4-D dataset; axes (z, y, x[, c])."""
    import h5py

    datasets = {}

    def visit(found, node):
        if isinstance(node, h5py.Dataset):
            datasets[found] = node  # returns None: the visit goes on

    with h5py.File(path, "r") as fh:
        fh.visititems(visit)
        name, dataset = _pick_array(datasets, name, path)
        source = _OnDemand(partial(_read_dataset, str(path), name), dataset.shape, dataset.dtype, dataset.chunks)
    return _array(source, chunks), None, None


def _read_zarr(path, name, level, chunks):
    """A Zarr array (v2 or v3), or one level of an OME-Zarr multiscale image with its spacing and origin."""
    import zarr

    def arrays(group, prefix=""):
        """{name from the store's top: array} of the arrays in ``group`` (at ``prefix``), at any depth."""
        return {prefix + n: a for n, a in group.members(max_depth=None) if isinstance(a, zarr.Array)}

    node = zarr.open(str(path), mode="r")
    if name is not None:
        if not isinstance(node, zarr.Group):
            raise FileFormatError(f"{path} is one Zarr array, with no array /{name} inside; leave out ':/{name}'")
        if name not in node:
            _pick_array(arrays(node), name, path)  # says which arrays there are
        node = node[name]
    where = f"{path}:/{name}" if name else str(path)
    if isinstance(node, zarr.Group):
        attrs = node.attrs.asdict()
        ome = attrs.get("ome", attrs)  # NGFF 0.5 keeps its metadata under "ome"
        if "multiscales" in ome:
            return _read_ome_zarr(node, ome["multiscales"], where, level, chunks)
        node = _pick_array(arrays(node, f"{name}/" if name else ""), None, path)[1]
    elif len(node.shape) not in (3, 4):
        raise FileFormatError(f"{where} holds an array of shape {node.shape}; clwave reads a 3-D (z, y, x) or "
                              "4-D (z, y, x, c) array")
    if level is not None:
        raise InputError(f"level= applies to OME-Zarr multiscale images, and {where} is a plain Zarr array; leave "
                         "it out", cli=f"--level applies to OME-Zarr multiscale images, and {where} is a plain "
                                        "Zarr array; leave it out")
    return _array(node, chunks), None, None


# NGFF axis name -> its role in _array; units of length in metres (the NGFF list: UDUNITS-2 names)
_NGFF_ROLES = {"z": "s", "y": "s", "x": "s", "c": "c", "t": "t"}
_SI_PREFIXES = {"yocto": -24, "zepto": -21, "atto": -18, "femto": -15, "pico": -12, "nano": -9, "micro": -6,
                "milli": -3, "centi": -2, "deci": -1, "": 0, "hecto": 2, "kilo": 3, "mega": 6, "giga": 9,
                "tera": 12, "peta": 15, "exa": 18, "zetta": 21, "yotta": 24}
_METRES = {prefix + "meter": Fraction(10) ** power for prefix, power in _SI_PREFIXES.items()} | {
    "angstrom": Fraction(10) ** -10, "inch": Fraction("0.0254"), "foot": Fraction("0.3048"),
    "mile": Fraction("1609.344"), "parsec": Fraction("3.0857e16")}  # exact: 1 micrometer is 1000.0 nanometer


def _read_ome_zarr(group, multiscales, where, level, chunks):
    """Level ``level`` (default 0) of the first OME-Zarr (NGFF 0.4/0.5) multiscale image in ``group``: axes named
    z, y, x, an optional c (channels, moved last) and t (length 1, dropped); spacing and origin from the scale
    and translation of the level and of the whole image (NGFF puts voxel centres at integer indices, so the
    translation is the first voxel's centre)."""
    def bad(problem):
        return FileFormatError(f"{where}: its OME-Zarr metadata {problem}")

    image = multiscales[0] if isinstance(multiscales, list) and multiscales else None
    if not isinstance(image, dict):
        raise bad(f"holds multiscales {multiscales!r}, not a list of images")
    axes = [a if isinstance(a, dict) else {"name": a} for a in image.get("axes") or []]
    names = [str(a.get("name", "")).lower() for a in axes]
    if not {"z", "y", "x"} <= set(names) <= set(_NGFF_ROLES) or len(set(names)) < len(names):
        raise bad(f"names axes {names}; clwave reads axes z, y, x, with an optional c (channels) and t (time)")
    datasets = image.get("datasets")
    if not isinstance(datasets, list) or not datasets or not all(isinstance(d, dict) and "path" in d
                                                                 for d in datasets):
        raise bad(f"lists datasets {datasets!r}, not the levels' paths")
    if level is None:
        level = 0
    if isinstance(level, (bool, np.bool_)) or not isinstance(level, (int, np.integer)) \
            or not 0 <= level < len(datasets):
        shapes = [tuple(group[d["path"]].shape) if d["path"] in group else "missing" for d in datasets]
        levels = ", ".join(f"{i} {s}" for i, s in enumerate(shapes))
        raise InputError(f"level={level!r} does not exist in the OME-Zarr image {where}; its levels: {levels}",
                         cli=f"--level {level} does not exist in the OME-Zarr image {where}; its levels: {levels}")
    path = datasets[level]["path"]
    if path not in group:
        raise bad(f"names array {path!r} for level {level}, which the store does not hold")
    array = group[path]
    if len(array.shape) != len(names):
        raise bad(f"names {len(names)} axes {names}, but level {level} ({path}) has shape {array.shape}")
    if "t" in names and array.shape[names.index("t")] != 1:
        raise FileFormatError(f"{where} holds {array.shape[names.index('t')]} time points (axis t); clwave reads "
                              "one volume: write one time point to a store of its own")

    scale, translation = np.ones(len(names)), np.zeros(len(names))
    for transforms in (datasets[level].get("coordinateTransformations") or [],
                       image.get("coordinateTransformations") or []):  # the level's, then the image's
        for transform in transforms:
            kind = transform.get("type") if isinstance(transform, dict) else None
            if kind == "identity":
                continue
            values = np.asarray(transform.get(kind) if kind in ("scale", "translation") else [], float)
            if values.shape != (len(names),) or not np.all(np.isfinite(values)):
                raise bad(f"has the coordinate transformation {transform!r}; clwave reads a scale and a "
                          f"translation of {len(names)} finite numbers each, one per axis {names}")
            if kind == "scale":
                scale, translation = scale * values, translation * values
            else:
                translation = translation + values
    zyx = [names.index(a) for a in "zyx"]
    if np.any(scale[zyx] <= 0):
        raise bad(f"scales the axes {names} by {scale.tolist()}; the z, y, x scale must be positive")
    units = [axes[i].get("unit") for i in zyx]
    if len(set(units)) > 1:  # convert to the x axis's unit
        if not all(u in _METRES for u in units):
            raise bad(f"gives the z, y, x axes the units {units}; clwave converts different units of length "
                      f"only ({', '.join(_METRES)})")
        factor = np.array([float(_METRES[u] / _METRES[units[2]]) for u in units])
        scale[zyx], translation[zyx] = scale[zyx] * factor, translation[zyx] * factor

    data = _array(array, chunks, "".join(_NGFF_ROLES[n] for n in names))
    data = data[tuple(0 if n == "t" else slice(None) for n in names)]
    names = [n for n in names if n != "t"]
    data = data.transpose([names.index(a) for a in "zyxc" if a in names])
    shape = np.array(data.shape[:3])
    spacing = tuple(float(d) for d in scale[zyx])
    origin = translation[zyx] + scale[zyx] * (shape - 1) / 2  # the volume's centre, (z, y, x)
    return data, spacing, tuple(float(o) for o in origin[::-1])


def _read_dicom_folder(folder, series, progress_bar):
    """One DICOM series: slices sorted along their normal, rescaled, in RAS."""
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
    dz = float(np.median(gaps))
    if np.ptp(gaps) > 0.01 * dz:
        log.warning("DICOM series %s: slice gaps range from %.4g to %.4g mm; the volume uses "
                    "the median %.4g mm (is a slice missing?)", uid, gaps.min(), gaps.max(), dz)
    dy, dx = (float(s) for s in headers[order[0]][1].PixelSpacing)  # row spacing, column spacing

    data_zyx = _read_slices([headers[i][0] for i in order], _dicom_pixels,
                            "reading DICOM slices", progress_bar)
    # index (column, row, slice) -> LPS patient coordinates (mm)
    affine_lps = np.eye(4)
    affine_lps[:3, :3] = np.column_stack([row_dir * dx, col_dir * dy, normal * dz])
    affine_lps[:3, 3] = positions[order[0]]
    data_ijk = data_zyx.transpose((2, 1, 0) + tuple(range(3, data_zyx.ndim)))
    return _to_canonical(data_ijk, _LPS_TO_RAS @ affine_lps)


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
    for path in _folder_files(folder):
        with _reading(path):
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
