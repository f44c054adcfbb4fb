"""One dataset of an HDF5 file (``.h5``, ``.hdf5``, ``.hdf``), read chunk by chunk; never one whose data is
in another file (external storage, a virtual dataset, an external or soft link)."""

from __future__ import annotations

import itertools
import math
from functools import partial

from ...errors import FileFormatError
from ..hdf5_safety import check_chunks, check_filters_available, check_stored_inside
from .shared import OnDemand, as_array, pick_array


#: a dataset of more than MAX_SMALL_CHUNKS chunks of fewer than SMALL_CHUNK voxels is refused (_check_chunk_size): a
#: read of 128³ voxels would span up to 2^14 of them, some 64 MB of HDF5's bookkeeping
SMALL_CHUNK, MAX_SMALL_CHUNKS = 128, 1 << 14


def read_hdf5(path, name, chunks, fits=None):
    """One dataset of an HDF5 file: the one named, or the file's only 3-D/4-D dataset; axes (z, y, x[, c])."""
    import h5py

    datasets = {}

    def visit(found, node):
        if isinstance(node, h5py.Dataset):
            datasets[found] = node  # returns None: the visit goes on

    with h5py.File(path, "r") as fh:
        fh.visititems(visit)
        name, dataset = pick_array(datasets, name, path)  # reached by hard links: visititems follows no other
        try:  # the volume's bytes are in this file (docs/chunked.md §4)
            check_stored_inside(dataset.id, f"{path}:/{name}")
        except ValueError as exc:
            raise FileFormatError(f"{exc}; clwave reads volumes stored in the file itself") from None
        try:
            check_filters_available(dataset.id, f"{path}:/{name}")
        except ValueError as exc:
            raise FileFormatError(f"{exc}; write it again without that filter, or with one of hdf5plugin's") from None
        _check_chunk_size(dataset, f"{path}:/{name}")
        source = OnDemand(partial(_read_dataset, str(path), name), dataset.shape, dataset.dtype, dataset.chunks)
    return as_array(source, chunks, fits=fits, path=f"{path}:/{name}"), None, None


def _check_chunk_size(dataset, where):
    """Refuse a dataset of more than :data:`MAX_SMALL_CHUNKS` chunks of fewer than :data:`SMALL_CHUNK` voxels each:
    HDF5 keeps about 4 KB for each chunk a read spans (a 64³ read of 1-voxel chunks: 1 GB, measured), so a chunk of
    the volume (``CHUNK_BYTES``, thousands of them) outgrows the memory its voxels take thousands of times."""
    chunks = dataset.chunks
    if chunks is None or math.prod(chunks) >= SMALL_CHUNK:
        return
    count = math.prod(-(-n // c) for n, c in zip(dataset.shape, chunks))
    if count > MAX_SMALL_CHUNKS:
        raise FileFormatError(f"{where}: its chunks of {' x '.join(map(str, chunks))} voxels, {count:,} of them, are "
                              f"too small to read (HDF5 keeps about 4 KB for each chunk a read spans): write it again "
                              f"in chunks of {SMALL_CHUNK} voxels or more, e.g. h5repack -l CHUNK=64x64x64")


def _read_dataset(path, name, index):
    """``index`` (slices) of the dataset, its chunks there checked first (:func:`.hdf5_safety.check_chunks`: none
    decodes past its size)."""
    import h5py
    import hdf5plugin  # noqa: F401  (its filters, in a worker process too)

    with h5py.File(path, "r") as fh:
        dataset = fh[name]
        if dataset.chunks is not None:
            check_chunks(dataset.id, path, f"/{name}", _covered(index, dataset.shape, dataset.chunks))
        return dataset[index]


def _covered(index, shape, chunks):
    """The first element of each chunk that ``index`` (a tuple of slices) covers; None (every chunk) for another."""
    if not (isinstance(index, tuple) and all(isinstance(s, slice) for s in index)):
        return None
    index += (slice(None),) * (len(shape) - len(index))
    spans = [range(*s.indices(n)[:2]) for s, n in zip(index, shape)]
    return itertools.product(*(range(r.start // c * c, r.stop, c) for r, c in zip(spans, chunks)))
