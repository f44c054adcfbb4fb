"""NRRD files (``.nrrd``, ``.nhdr`` with its data file) through pynrrd, in RAS+."""

from __future__ import annotations

import bz2
import math
import re
import shlex
import warnings
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from ...errors import FileFormatError
from .inflate import GZIP, decompressed
from .shared import Declared, check_declared_size, check_whole, not_a_file, note, to_canonical

_NRRD_SPACE_SIGNS = {
    "right-anterior-superior": (1, 1, 1), "ras": (1, 1, 1),
    "left-anterior-superior": (-1, 1, 1), "las": (-1, 1, 1),
    "left-posterior-superior": (-1, -1, 1), "lps": (-1, -1, 1),
    # a left-handed frame taken as RAS would mirror the object; its third axis is reversed instead (as a
    # left-handed screen frame, z into the screen, becomes OpenGL's right-handed one): x and y kept
    "3d-left-handed": (1, 1, -1),
}

#: the encodings pynrrd reads
_ENCODINGS = ("raw", "gzip", "gz", "bzip2", "bz2", "ascii", "text", "txt")


def read_nrrd(path, fits=None, warn_spacing=True):
    """NRRD/NHDR through pynrrd (gzip and bzip2 data through :func:`_inflated`): ``space directions`` and ``space``
    give the RAS affine; the header is checked (its declared size against the data and :func:`check_whole`) before
    the data is read.  An unknown spacing
    (``spacings: nan``) is taken as 1, with a warning unless ``warn_spacing`` is false (one was given)."""
    import nrrd

    with open(path, "rb") as fh:
        header = _read_header(path, fh)
        _check_nrrd_size(path, header, fh.tell())
        sizes = [int(n) for n in header["sizes"]]
        directions = header.get("space directions")
        if directions is not None:
            directions = np.asarray(directions, float)
            _check_directions(path, directions, header.get("space origin"))
            spatial = [a for a in range(len(sizes)) if np.all(np.isfinite(directions[a]))]
        elif "kinds" in header:
            spatial = [a for a, kind in enumerate(header["kinds"]) if kind.lower() in ("domain", "space")]
        else:
            spatial = list(range(len(sizes)))
        others = [a for a in range(len(sizes)) if a not in spatial]
        width = directions.shape[1] if directions is not None else 3
        if len(spatial) != 3 or len(others) > 1 or width != 3:
            raise FileFormatError(
                f"{path} has {len(sizes)} axes of sizes {tuple(sizes)} in a {width}-D space; clwave "
                "reads 3 spatial axes in 3-D space plus at most one channel axis")
        if directions is not None and _singular(directions[spatial]):
            raise FileFormatError(f"{path}: its space directions {_rows(directions[spatial])} are singular (a zero or "
                                  "repeated direction) and span no 3-D grid; correct the header's space directions")
        affine = np.eye(4)
        if directions is not None:
            affine[:3, :3] = directions[spatial].T
            affine[:3, 3] = header.get("space origin", np.zeros(3))
        else:
            spacings = np.asarray(header.get("spacings", np.ones(len(sizes))), float)[spatial]
            if np.isinf(spacings).any():  # NaN is NRRD's unknown spacing; infinity none
                raise FileFormatError(f"{path}: its spacings (dz, dy, dx) {', '.join(map(str, spacings[::-1]))} "
                                      "include an infinite one; correct the header's spacings (nan where unknown)")
            if warn_spacing and not np.all(np.isfinite(spacings)):
                note(f"{path}: its spacing (dz, dy, dx) {', '.join(map(str, spacings[::-1]))} is unknown (nan) on "
                     f"some axes; taken as 1 there: give spacing= (--spacing DZ,DY,DX) for the true one")
            affine[:3, :3] = np.diag(np.where(np.isfinite(spacings), spacings, 1.0))
        # other spaces (scanner-xyz, 3D-right-handed, none) are right-handed: taken as RAS
        affine = np.diag(_NRRD_SPACE_SIGNS.get(str(header.get("space", "")).lower(), (1, 1, 1)) + (1,)) @ affine
        dtype = nrrd.reader._determine_datatype(header)
        try:
            check_whole(path, [sizes[a] for a in spatial + others], dtype, fits)
        except Declared as declared:  # describe(): its place from the header, its stream as the read weighs it
            declared.place([sizes[a] for a in spatial], affine)
            if str(header.get("encoding", "raw")).lower() in _DECOMPRESSORS:
                _inflated(path, header, fh, dtype, sizes, keep=False)
            raise
        if str(header.get("encoding", "raw")).lower() in _DECOMPRESSORS:
            data = _inflated(path, header, fh, dtype, sizes)
        else:
            data = nrrd.read_data(header, fh, str(path))  # index_order 'F': axes in file order, fastest first
    return to_canonical(np.moveaxis(data, others, list(range(3, data.ndim))), affine)


def world_unit(path) -> str | None:
    """The unit of the header's ``space units`` ("mm", "um", "m"; the same on every axis), else "mm" where it names
    a ``space`` (an anatomical one: millimetres by convention), else None."""
    with open(path, "rb") as fh:
        header = _read_header(path, fh)
        fh.seek(0)
        line = re.search(rb"^space units: *(.*)$", fh.read(1 << 16), re.M) if "space units" in header else None
    given = header.get("space units", ())
    if line is not None and not line.group(1).isascii():  # pynrrd drops what is not ASCII: "µm" read as metres
        given = shlex.split(line.group(1).decode("utf-8", "replace"))
    units = {str(u).lower().replace("µ", "u").replace("μ", "u") for u in given}
    if units:
        return units.pop() if len(units) == 1 and units <= {"mm", "um", "m", "cm"} else None
    return "mm" if "space" in header else None


def _read_header(path, fh):
    """pynrrd's header; one naming its data files line by line (``data file: LIST``) is refused by name."""
    import nrrd

    try:
        with warnings.catch_warnings():  # a number beyond int64 (sizes: 1e20) is cast with a warning, to nonsense
            warnings.simplefilter("error", RuntimeWarning)
            return nrrd.read_header(fh)
    except RuntimeWarning as exc:
        raise FileFormatError(f"{path}: its header holds a number beyond the range of its field ({exc}); correct the "
                              "header") from None
    except ValueError:  # pynrrd reads the list's file names as broken fields
        fh.seek(0)
        if re.search(rb"^data ?file: *LIST", fh.read(1 << 16), re.M):
            raise _several_files(path, "LIST") from None
        raise


def _several_files(path, name) -> FileFormatError:
    return FileFormatError(f"{path} spreads its data over several files (data file: {name}); clwave reads one data "
                           "file: join them into one raw file and name it in the header")


def _singular(directions) -> bool:
    """Whether three directions span no 3-D grid: a zero or repeated one, by the determinant of the directions scaled
    to their largest component (at any scale: a huge one's determinant overflowed, and its size is Volume's check)."""
    largest = np.abs(directions).max(axis=1, keepdims=True)
    if not largest.all():
        return True
    scaled = directions / largest
    return abs(np.linalg.det(scaled)) <= 1e-9 * np.prod(np.linalg.norm(scaled, axis=1))


def _rows(directions) -> str:
    return " ".join("(" + ",".join(f"{v:g}" for v in row) + ")" for row in directions)


def _check_directions(path, directions, origin):
    """Refuse ``space directions`` with nan or inf in a spatial axis (a channel axis is all ``none``, read as nan)
    and a non-finite ``space origin``."""
    broken = ~np.isfinite(directions).all(axis=1) & ~np.isnan(directions).all(axis=1)
    if broken.any() or (origin is not None and not np.all(np.isfinite(origin))):
        found = f"space directions {_rows(directions)}" if broken.any() else f"space origin {_rows([origin])}"
        raise FileFormatError(f"{path}: its {found} hold nan or inf; each spatial axis needs a finite direction and "
                              "origin (a channel axis: none): correct the header")


def _data_file(path, header):
    """The detached data file a NRRD header names (``data file``), or None where the data follows the header.  An
    untrusted header must not read other files: one resolving outside the header's folder is refused, and so are
    a ``%d`` pattern of several files, which pynrrd does not read."""
    name = header.get("data file", header.get("datafile"))
    if name is None:
        return None
    name = str(name)
    words = name.split()
    if len(words) >= 4 and "%" in words[0]:
        raise _several_files(path, name)
    folder = Path(path).resolve().parent
    target = (folder / name).resolve()
    if not target.is_relative_to(folder):
        raise FileFormatError(f"{path} names the data file {name}, outside the header's folder {folder}; clwave "
                              "reads no files elsewhere for an untrusted header: put the data file beside the header "
                              "and name it there")
    if target.exists() and not target.is_file():
        raise not_a_file(target)
    return target


def _check_nrrd_size(path, header, offset):
    """What pynrrd's read refuses, refused from the header (so ``clwave info`` refuses it too): a ``dimension`` not
    the number of ``sizes``, an encoding or a ``type`` it does not read, a line or byte skip it does not take, a
    missing detached data file; and a header that declares more voxels than its raw or gzip data holds (attached
    data starting at ``offset``) before pynrrd allocates them, or fewer than its raw data holds (pynrrd reads all of
    it).  A corrupt compressed stream is found by the read alone."""
    import nrrd

    encoding = str(header.get("encoding", "raw")).lower()
    sizes = [int(n) for n in header["sizes"]]
    if header.get("dimension") != len(sizes):
        raise FileFormatError(f"{path}: its header's dimension {header.get('dimension')} is not the number of its "
                              f"sizes ({' '.join(map(str, sizes))}); correct the header")
    if encoding not in _ENCODINGS or str(header.get("type")).lower() == "block":
        found = f"type {header['type']}" if encoding in _ENCODINGS else f"encoding {header['encoding']}"
        raise FileFormatError(f"{path}: its {found} is not one the NRRD reader (pynrrd) reads; write it as raw, gzip, "
                              f"bzip2 or text voxels of a number type")
    lines, skip = _skips(header)
    if lines < 0 or skip < -1:
        raise FileFormatError(f"{path}: its line skip {lines} or byte skip {skip} is negative (a byte skip may be -1: "
                              f"the data at the end); correct the header")
    if skip < 0 and encoding in _DECOMPRESSORS:
        raise FileFormatError(f"{path}: its byte skip {skip} is negative; a {encoding} stream is read from its start "
                              "(Teem reads no byte skip of -1 in one): give the count of bytes to skip")
    detached = _data_file(path, header)
    if detached is not None:  # a detached header: the data is a file of its own
        if not detached.is_file():
            raise FileFormatError(f"{path} names the data file {detached.name}, which is not beside it; put it there")
        path, offset = detached, 0
    if min(sizes) < 1:
        raise FileFormatError(f"{path}: its header declares sizes {' '.join(map(str, sizes))}; every axis needs at "
                              "least one voxel")
    if encoding not in ("raw", "gzip", "gz") or skip == -1:
        return
    if lines:  # the lines skipped before the data (raw) or the stream (gzip)
        with open(path, "rb") as fh:
            fh.seek(offset)
            for _ in range(lines):
                fh.readline()
            offset = fh.tell()
    nbytes = math.prod(sizes) * nrrd.reader._determine_datatype(header).itemsize
    if encoding != "raw":  # the byte skip counts bytes of the stream, which starts after the header
        check_declared_size(path, skip, nbytes, sizes[::-1], gzip=True, start=offset, longer=True)
        return
    check_declared_size(path, offset + skip, nbytes, sizes[::-1], gzip=False)
    if Path(path).stat().st_size > offset + skip + nbytes:
        raise FileFormatError(f"{path}: its header declares {' x '.join(map(str, sizes[::-1]))} voxels "
                              f"({nbytes:,} bytes) but the file holds {Path(path).stat().st_size - offset - skip:,} "
                              f"bytes after its header; its header is wrong or the file is not what it says")


def _skips(header) -> tuple:
    """The header's ``(line skip, byte skip)``, 0 where not given (each key with or without its space, as pynrrd)."""
    return tuple(int(header.get(k, header.get(k.replace(" ", ""), 0)) or 0) for k in ("line skip", "byte skip"))


#: each compressed encoding's decompressor (a new one for each gzip member or bzip2 stream) and the first bytes of one
_DECOMPRESSORS = {"gzip": GZIP, "bzip2": (bz2.BZ2Decompressor, b"BZh")}
_DECOMPRESSORS.update(gz=_DECOMPRESSORS["gzip"], bz2=_DECOMPRESSORS["bzip2"])


def _inflated(path, header, fh, dtype, sizes, keep=True) -> np.ndarray | None:
    """A gzip or bzip2 NRRD's data (after the header read from ``fh``, or in its detached data file), every gzip
    member or bzip2 stream, decompressed into its array as pynrrd's ``read_data`` lays it out, never one byte past
    the ``byte skip`` and voxels its header declares: a gzip trailer counts its member alone, modulo 2^32, and
    pynrrd inflates all of the first member before it compares.  ``line skip`` counts lines of the file before the
    stream, ``byte skip`` bytes of the stream, as Teem reads them (pynrrd skips the bytes in both).  Without ``keep``
    (``clwave info``) the stream is decompressed and weighed alike, kept nowhere: None."""
    lines, skip = _skips(header)  # checked by _check_nrrd_size
    encoding = str(header["encoding"]).lower()
    nbytes = math.prod(sizes) * dtype.itemsize
    voxels = " x ".join(map(str, sizes[::-1]))
    buffer = np.empty(nbytes, np.uint8) if keep else None
    held = 0  # bytes of the stream decompressed
    with ExitStack() as files:
        detached = _data_file(path, header)
        source = files.enter_context(open(detached, "rb")) if detached is not None else fh
        for _ in range(lines):
            source.readline()
        for piece in decompressed(source, *_DECOMPRESSORS[encoding], skip + nbytes + 1):
            held += len(piece)
            if held > skip + nbytes:
                raise FileFormatError(f"{path}: its {encoding} stream holds more than the {skip + nbytes:,} bytes its "
                                      f"header declares ({voxels} voxels); its header is wrong or the file is not "
                                      "what it says")
            if keep:
                used = piece[max(skip - held + len(piece), 0):]
                buffer[held - skip - len(used):held - skip] = np.frombuffer(used, np.uint8)
    if held < skip + nbytes:
        raise FileFormatError(f"{path}: its header declares {voxels} voxels ({nbytes:,} bytes) but its {encoding} "
                              f"stream holds {max(held - skip, 0):,} bytes; it is truncated or its header is wrong")
    return buffer.view(dtype).reshape(sizes[::-1]).T if keep else None
