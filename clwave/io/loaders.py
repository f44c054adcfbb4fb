"""Read volumes from files: one :func:`load` for every supported format.

The result is a (z, y, x[, c]) float32 :class:`~clwave.model.volume.Volume`; medical formats
(NIfTI, NRRD, DICOM) are put in the canonical RAS+ orientation with spacing and origin in scanner
millimetres, the others keep their array axes (docs/coordinates.md §1).
"""

from __future__ import annotations

import logging
import os
import re
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import ClwaveError, FileFormatError, InputError, finite_number
from .progress import progress
from ..model.volume import Volume

log = logging.getLogger(__name__)

SUPPORTED = (".npy, .nii, .nii.gz, .nrrd, .nhdr, .tif/.tiff (multi-page, or a folder of "
             "2-D slices), a folder of DICOM files, .raw (with shape= and dtype=)")

_TIFF_SUFFIXES = (".tif", ".tiff")
_FILE_KINDS = {".npy": "npy", ".nii": "nifti", ".nii.gz": "nifti", ".nrrd": "nrrd",
               ".nhdr": "nrrd", ".tif": "tiff", ".tiff": "tiff", ".raw": "raw"}

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


def load(path, *, shape=None, dtype=None, spacing=None, byte_order=None, series=None,
         background=0.0, hu_to_mu=False, mu_water=0.0193, progress_bar=None) -> Volume:
    """Load a volume file or folder as a :class:`Volume` (RAS+ for medical data).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy``, ``.nii``, ``.nii.gz``, ``.nrrd``, ``.nhdr``, a multi-page
        ``.tif``/``.tiff``, a folder of 2-D TIFF slices (stacked in natural name
        order: ``slice2`` before ``slice10``), a folder of DICOM files (other files
        in it are ignored), or ``.raw``.
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
    kind = _kind(path)
    if kind != "raw":
        _reject_unused(kind, shape=shape, dtype=dtype, byte_order=byte_order)
    if kind != "dicom":
        _reject_unused(kind, series=series)

    with _reading(path):
        if kind == "raw":
            data, file_spacing, origin = _read_raw(path, shape, dtype, byte_order)
        elif kind == "npy":
            data, file_spacing, origin = np.load(path, allow_pickle=False), None, None
        elif kind == "nifti":
            data, file_spacing, origin = _read_nifti(path)
        elif kind == "nrrd":
            data, file_spacing, origin = _read_nrrd(path)
        elif kind == "tiff":
            data, file_spacing, origin = _read_tiff(path), None, None
        elif kind == "tiff-folder":
            data, file_spacing, origin = _read_tiff_folder(path, progress_bar), None, None
        else:
            data, file_spacing, origin = _read_dicom_folder(path, series, progress_bar)

    data = np.asarray(data)
    if data.dtype.kind == "f" and data.dtype.itemsize > 4 and data.size:
        top = float(np.nanmax(np.abs(np.where(np.isfinite(data), data, 0.0))))
        if top > float(np.finfo(np.float32).max):
            raise InputError(f"{path} holds values up to {top:.3g}, beyond float32's range (3.4e38); rescale "
                             f"the data first")
    if data.dtype.kind in "biuf":  # anything else: Volume explains the dtype problem
        data = np.ascontiguousarray(data, dtype=np.float32)
        if hu_to_mu:
            _hu_to_mu(data, mu_water)
        if background:
            data -= np.float32(background)
    return Volume(data,
                  spacing=spacing if spacing is not None else (file_spacing or 1.0),
                  origin=origin if origin is not None else (0.0, 0.0, 0.0))


# --------------------------------------------------------------------------- shared steps

def _kind(path: Path) -> str:
    """Format of ``path`` from its extension, or the content of a folder."""
    if path.is_dir():
        return "tiff-folder" if _tiff_files(path) else "dicom"
    name = path.name.lower()
    suffix = ".nii.gz" if name.endswith(".nii.gz") else path.suffix.lower()
    if not path.exists():
        raise FileFormatError(f"no file or folder at {path}; supported inputs: {SUPPORTED}")
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
        needs = "DICOM folders" if "series" in given else ".raw files"
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


def _hu_to_mu(data, mu_water):
    """In place: Hounsfield units -> attenuation, clipped at 0 (air, -1000 HU, is exactly 0)."""
    if data.ndim != 3:
        raise InputError(f"hu_to_mu converts scalar CT volumes, but this one has "
                         f"{data.shape[3]} channels; leave hu_to_mu off")
    data += 1000.0
    data *= np.float32(mu_water / 1000.0)
    np.maximum(data, 0.0, out=data)


def _to_canonical(array_ijk, affine_ras):
    """Reorient an array with an index -> RAS affine to ``(z, y, x)`` RAS+ axes.

    Parameters
    ----------
    array_ijk : ndarray, shape (ni, nj, nk) or (ni, nj, nk, c)
        Voxels indexed like the affine's columns.
    affine_ras : ndarray, shape (4, 4)
        Maps ``(i, j, k, 1)`` to RAS world coordinates (mm).

    Returns
    -------
    array_zyx : ndarray
        Permuted and flipped view: axis 0 -> superior, 1 -> anterior, 2 -> right.
    spacing_zyx : tuple of float
        ``(dz, dy, dx)``, the lengths of the reoriented affine's columns.
    origin_xyz : tuple of float
        RAS position of the volume centre.
    """
    from nibabel.affines import obliquity
    from nibabel.orientations import apply_orientation, inv_ornt_aff, io_orientation

    ornt = io_orientation(affine_ras)
    array_xyz = apply_orientation(array_ijk, ornt)
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

def _read_raw(path, shape, dtype, byte_order):
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
    return np.fromfile(path, dtype=dt).reshape(shape), None, None


def _read_nifti(path):
    """NIfTI-1/2 through nibabel: RGB24/RGBA32 become channels; time series are refused."""
    import nibabel

    image = nibabel.load(path, mmap=False)
    _check_declared_size(path, int(image.header["vox_offset"]),
                         int(np.prod(image.shape)) * image.header.get_data_dtype().itemsize, image.shape)
    data = np.asanyarray(image.dataobj)  # applies scl_slope / scl_inter
    if data.ndim > 3:
        # NIfTI keeps time on the 4th axis and vector components on the 5th
        if data.shape[3] != 1 or any(n != 1 for n in data.shape[5:]):
            raise FileFormatError(
                f"{path} holds a NIfTI image of shape {data.shape}; clwave reads one 3-D "
                "volume (vector components on the 5th axis become channels): extract one "
                "volume first, e.g. with nibabel.funcs.four_to_three")
        data = data.reshape(data.shape[:3] + data.shape[4:5])
    if data.dtype.names:  # RGB24 / RGBA32 structured samples
        data = np.stack([data[name] for name in data.dtype.names], axis=-1)
    return _to_canonical(data, image.affine)


def _check_declared_size(path, offset, nbytes, shape):
    """Refuse a header that declares more data than the file holds, before anything is allocated
    (gzip: its trailer's size of the uncompressed stream, modulo 2^32)."""
    path = Path(path)
    if path.name.lower().endswith(".gz"):
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
