"""NRRD files (``.nrrd``, ``.nhdr`` with its data file) through pynrrd, in RAS+."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import FileFormatError
from .shared import check_declared_size, to_canonical

_NRRD_SPACE_SIGNS = {
    "right-anterior-superior": (1, 1, 1), "ras": (1, 1, 1),
    "left-anterior-superior": (-1, 1, 1), "las": (-1, 1, 1),
    "left-posterior-superior": (-1, -1, 1), "lps": (-1, -1, 1),
}


def read_nrrd(path):
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
    return to_canonical(data, np.diag(signs + (1,)) @ affine)


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
    if min(sizes) < 1:
        raise FileFormatError(f"{path}: its header declares sizes {' '.join(map(str, sizes))}; every axis needs at "
                              "least one voxel")
    nbytes = int(np.prod(sizes, dtype=np.float64)) * nrrd.reader._determine_datatype(header).itemsize
    skip = max(int(header.get("byte skip", 0) or 0), 0)
    check_declared_size(path, offset + skip, nbytes, sizes[::-1], gzip=encoding != "raw")
