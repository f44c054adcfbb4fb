"""One dataset of an HDF5 file (``.h5``, ``.hdf5``, ``.hdf``), read chunk by chunk; never one whose data is
in another file (external storage, a virtual dataset, an external or soft link)."""

from __future__ import annotations

import itertools
import math
from functools import partial

from ...errors import FileFormatError
from ..hdf5_safety import DEFLATE, SHUFFLE, check_chunks, check_filters_available, check_stored_inside
from .inflate import inflated
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
            raise FileFormatError(f"{exc}: write it again with gzip, lzf or Zstandard, e.g. h5repack -f "
                                  "GZIP=4 IN OUT") from None
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
    decodes past its size); a deflate (and shuffle) dataset's chunks decoded here, once, to their size and no further
    (:func:`_read_inflated`)."""
    import h5py
    import hdf5plugin  # noqa: F401  (its filters, in a worker process too)

    with h5py.File(path, "r") as fh:
        dataset = fh[name]
        if dataset.chunks is None:
            return dataset[index]
        plist = dataset.id.get_create_plist()
        codes = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
        covered = _covered(index, dataset.shape, dataset.chunks)
        if codes in ([DEFLATE], [SHUFFLE, DEFLATE]) and covered is not None:
            return _read_inflated(dataset, index, covered, len(codes) == 2, f"/{name}")
        check_chunks(dataset.id, path, f"/{name}", covered)
        return dataset[index]


def _read_inflated(dataset, index, covered, shuffled, member):
    """``index`` (a tuple of slices, or ``...``) of a chunked ``dataset`` filtered by deflate (and shuffle) alone,
    from the chunks that start at ``covered``: each chunk's stored bytes read and inflated once, to the chunk's bytes
    and no further (:func:`.inflate.inflated`), where HDF5's filter would grow its buffer as far as the stream goes."""
    import zlib

    import numpy as np

    index = () if index is Ellipsis else index
    index += (slice(None),) * (dataset.ndim - len(index))
    bounds = [s.indices(n)[:2] for s, n in zip(index, dataset.shape)]
    out = np.empty([stop - start for start, stop in bounds], dataset.dtype)
    chunk, size = dataset.chunks, dataset.dtype.itemsize
    most = math.prod(chunk) * size
    for offset in covered:
        data, mask = None, 0
        if dataset.id.get_chunk_info_by_coord(tuple(offset)).byte_offset is not None:
            mask, data = dataset.id.read_direct_chunk(tuple(offset))
        where = f"member {member}, its chunk at {tuple(offset)}"
        if data is None:  # never written: the fill value
            block = np.full(chunk, dataset.fillvalue, dataset.dtype)
        else:
            if not mask >> shuffled & 1:  # deflate: the pipeline's last filter, skipped where its bit is set
                try:
                    data = inflated(data, zlib.decompressobj, None, most, "a deflate chunk")
                except (ValueError, zlib.error) as exc:
                    raise ValueError(f"{where}: {exc}") from None
            if len(data) != most:
                raise ValueError(f"{where}: holds {len(data):,} bytes, not the {most:,} of its chunk (truncated or "
                                 "corrupt)")
            if shuffled and not mask & 1:
                data = np.frombuffer(data, np.uint8).reshape(size, -1).T.tobytes()
            block = np.frombuffer(data, dataset.dtype).reshape(chunk)
        part = tuple(slice(max(start, o), min(stop, o + c)) for (start, stop), o, c in zip(bounds, offset, chunk))
        out[tuple(slice(p.start - start, p.stop - start) for p, (start, _) in zip(part, bounds))] = \
            block[tuple(slice(p.start - o, p.stop - o) for p, o in zip(part, offset))]
    return out


def _covered(index, shape, chunks):
    """The first element of each chunk that ``index`` (a tuple of slices, or ``...``) covers; None (every chunk) for
    another."""
    index = () if index is Ellipsis else index
    if not (isinstance(index, tuple) and all(isinstance(s, slice) and s.step in (None, 1) for s in index)):
        return None
    index += (slice(None),) * (len(shape) - len(index))
    spans = [range(*s.indices(n)[:2]) for s, n in zip(index, shape)]
    return itertools.product(*(range(r.start // c * c, r.stop, c) for r, c in zip(spans, chunks)))
