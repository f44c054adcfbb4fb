"""NRRD files (``.nrrd``, ``.nhdr`` with its data file) through pynrrd, in RAS+."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import FileFormatError
from .shared import check_declared_size, check_whole, log, to_canonical

_NRRD_SPACE_SIGNS = {
    "right-anterior-superior": (1, 1, 1), "ras": (1, 1, 1),
    "left-anterior-superior": (-1, 1, 1), "las": (-1, 1, 1),
    "left-posterior-superior": (-1, -1, 1), "lps": (-1, -1, 1),
    # a left-handed frame taken as RAS would mirror the object; its third axis is reversed instead (as a
    # left-handed screen frame, z into the screen, becomes OpenGL's right-handed one): x and y kept
    "3d-left-handed": (1, 1, -1),
}


def read_nrrd(path, fits=None, warn_spacing=True):
    """NRRD/NHDR through pynrrd: ``space directions`` and ``space`` give the RAS affine; the header is checked
    (its declared size against the data and :func:`check_whole`) before the data is read.  An unknown spacing
    (``spacings: nan``) is taken as 1, with a warning unless ``warn_spacing`` is false (one was given)."""
    import nrrd

    with open(path, "rb") as fh:
        header = nrrd.read_header(fh)
        _check_nrrd_size(path, header, fh.tell())
        sizes = [int(n) for n in header["sizes"]]
        directions = header.get("space directions")
        if directions is not None:
            directions = np.asarray(directions, float)
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
        check_whole(path, [sizes[a] for a in spatial + others], nrrd.reader._determine_datatype(header), fits)
        data = nrrd.read_data(header, fh, str(path))  # index_order 'F': axes in file order, fastest first
    data = np.moveaxis(data, others, list(range(3, data.ndim)))

    affine = np.eye(4)
    if directions is not None:
        affine[:3, :3] = directions[spatial].T
        affine[:3, 3] = header.get("space origin", np.zeros(3))
    else:
        spacings = np.asarray(header.get("spacings", np.ones(len(sizes))), float)[spatial]
        if warn_spacing and not np.all(np.isfinite(spacings)):
            log.warning("%s: its spacing (dz, dy, dx) %s is unknown (nan) on some axes; taken as 1 there: give "
                        "spacing= (--spacing DZ,DY,DX) for the true one", path, ", ".join(map(str, spacings[::-1])))
        affine[:3, :3] = np.diag(np.where(np.isfinite(spacings), spacings, 1.0))
    # other spaces (scanner-xyz, 3D-right-handed, none) are right-handed: taken as RAS
    signs = _NRRD_SPACE_SIGNS.get(str(header.get("space", "")).lower(), (1, 1, 1))
    return to_canonical(data, np.diag(signs + (1,)) @ affine)


def _check_nrrd_size(path, header, offset):
    """A NRRD header that declares more voxels than its raw or gzip data holds (attached data starting at
    ``offset``) is refused before pynrrd allocates them (other encodings, and a missing detached data file, are
    left to pynrrd)."""
    import nrrd

    encoding = str(header.get("encoding", "raw")).lower()
    if "data file" in header:  # a detached header: the data is a file of its own
        path, offset = Path(Path(path).parent, str(header["data file"])), 0
    if encoding not in ("raw", "gzip", "gz") or not Path(path).is_file():
        return
    if encoding != "raw":  # the gzip stream starts after the header; its trailer counts the stream alone
        offset = 0
    sizes = [int(n) for n in header["sizes"]]
    if min(sizes) < 1:
        raise FileFormatError(f"{path}: its header declares sizes {' '.join(map(str, sizes))}; every axis needs at "
                              "least one voxel")
    nbytes = int(np.prod(sizes, dtype=np.float64)) * nrrd.reader._determine_datatype(header).itemsize
    skip = max(int(header.get("byte skip", 0) or 0), 0)
    check_declared_size(path, offset + skip, nbytes, sizes[::-1], gzip=encoding != "raw")
