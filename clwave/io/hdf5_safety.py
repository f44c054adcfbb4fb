"""An untrusted HDF5 file, checked before any of its data or attributes is read (docs/chunked.md §4).

HDF5 can point outside the file (external raw storage, external links, virtual datasets), alias or loop
(soft links, several hard links to one object), run code that is not HDF5's (a filter loaded as a plugin),
and hold data whose reading allocates far more than the file's size (variable-length and reference types,
attributes read whole, a chunk that inflates far past its size: :func:`check_chunks`).
:func:`check_self_contained` walks every member through HDF5's low-level calls, which read object headers (and
compressed chunks, never decoded whole) only, and refuses anything a clwave writer does not make.
"""

from __future__ import annotations

import os

#: filters a writer of a .clw uses: deflate, shuffle, Fletcher-32, Zstandard (hdf5plugin's id)
WRITER_FILTERS = {1: "deflate", 2: "shuffle", 3: "fletcher32", 32015: "zstd"}
MAX_MEMBERS = 4096           # objects in a file (a .clw has 3 per channel group and a mask)
MAX_DEPTH = 4                # groups within groups (a .clw nests one deep)
MAX_ATTRIBUTES = 16          # per object
MIN_CHUNK = 64               # elements a chunk holds at least (or the whole dataset); a writer's hold 256 or more
#: filters whose chunk states its decoded size in its header (HDF5's szip, hdf5plugin's: they allocate that size)
STATED = {32015: "zstd", 32001: "blosc", 4: "szip"}
DEFLATE, SHUFFLE, FLETCHER32, LZF = 1, 2, 3, 32000
#: filters whose chunks a volume's read weighs before they are decoded (:func:`check_chunks`); shuffle and Fletcher-32
#: keep a chunk's size, lzf's decoder grows its buffer to at most 88 times a chunk's stored bytes (its longest match,
#: 264 bytes, takes 3), which a chunk stored in no more than its bytes bounds
BOUNDED = {DEFLATE: "deflate", SHUFFLE: "shuffle", FLETCHER32: "fletcher32", LZF: "lzf", **STATED}
#: zlib's deflateBound: a stream of n bytes stored is at most n + n >> 12 + n >> 14 + ... + 13 (its wrapper's 6 more)
DEFLATE_SLACK = 11
#: bytes of metadata (object headers, chunk indexes, attribute heaps) a file may hold beyond its datasets' data:
#: fixed, per object and per chunk, on top of the attributes' bound (a written .clw holds ~10 KB)
METADATA_BYTES, OBJECT_BYTES, CHUNK_BYTES = 1 << 16, 1 << 12, 64


def check_self_contained(h5, path, max_attribute) -> None:
    """Refuse (``ValueError`` naming the member) an HDF5 file ``h5`` at ``path`` holding anything but
    groups and datasets reached by one hard link each, stored contiguously or in chunks inside the file,
    filtered only by :data:`WRITER_FILTERS`, of integer or float elements, with few attributes of at most
    ``max_attribute`` bytes each; and a file whose bytes beyond its datasets' data could hold a larger
    attribute (a variable-length string lives in a heap its attribute does not measure)."""
    from h5py import h5o

    seen, data_bytes, chunks = set(), 0, 0
    pending = [(h5.id, "/", 0)]
    _check_attributes(h5.id, "/", max_attribute)
    while pending:
        group, name, depth = pending.pop()
        for link in _link_names(group, name):
            member = f"{name.rstrip('/')}/{link.decode(errors='replace')}"
            obj = h5o.open(group, link)
            info = h5o.get_info(obj)
            if info.rc != 1 or info.addr in seen:  # one name per object: no aliases, no loops
                raise ValueError(f"member {member} is linked from more than one place")
            seen.add(info.addr)
            if len(seen) > MAX_MEMBERS:
                raise ValueError(f"the file holds more than {MAX_MEMBERS} members")
            _check_attributes(obj, member, max_attribute)
            if info.type == h5o.TYPE_GROUP:
                if depth + 1 > MAX_DEPTH:
                    raise ValueError(f"member {member} nests groups deeper than {MAX_DEPTH}")
                pending.append((obj, member, depth + 1))
            elif info.type == h5o.TYPE_DATASET:
                stored, n_chunks = _check_dataset_storage(obj, member, path)
                data_bytes, chunks = data_bytes + stored, chunks + n_chunks
            else:
                raise ValueError(f"member {member} is a named datatype, not a group or dataset")
    allowed = data_bytes + max_attribute + METADATA_BYTES + OBJECT_BYTES * len(seen) + CHUNK_BYTES * chunks
    size = os.path.getsize(path)
    if size > allowed:
        raise ValueError(f"the file holds {size - data_bytes:,} bytes beyond its datasets' data, more than a "
                         f".clw's metadata takes ({allowed - data_bytes:,})")


def _link_names(group, name) -> list:
    """The names in ``group``, each refused unless a hard link (soft, external and user-defined links point
    elsewhere, or in a loop)."""
    from h5py import h5l

    names = []
    group.links.iterate(lambda n: names.append(n) if len(names) <= MAX_MEMBERS else 1)  # returns None: go on
    for link in names:
        kind = group.links.get_info(link).type
        if kind != h5l.TYPE_HARD:
            what = {h5l.TYPE_SOFT: "a soft link", h5l.TYPE_EXTERNAL: "an external link"}.get(kind, "a user link")
            raise ValueError(f"member {name.rstrip('/')}/{link.decode(errors='replace')} is {what}; a .clw "
                             "holds its members itself")
    return names


def _check_dataset_storage(dataset, member, path) -> tuple:
    """``(bytes stored, chunks)`` of a dataset, refused unless stored inside the file, contiguous or in chunks
    of at least :data:`MIN_CHUNK` elements, through the writer's filters only, of integer or float elements
    in an array of at most 3 dimensions."""
    from h5py import h5d, h5s, h5t

    plist = dataset.get_create_plist()
    layout = check_stored_inside(dataset, member)
    if layout not in (h5d.CONTIGUOUS, h5d.CHUNKED):
        raise ValueError(f"member {member} is a compact dataset, not stored contiguously or in chunks")
    for i in range(plist.get_nfilters()):
        code, _, _, label = plist.get_filter(i)
        if code not in WRITER_FILTERS:
            raise ValueError(f"member {member} is filtered by {label.decode(errors='replace')!r} (id {code}), "
                             f"which a .clw writer does not use")
    kind = dataset.get_type().get_class()
    if kind not in (h5t.INTEGER, h5t.FLOAT) or dataset.get_type().get_size() > 8:
        raise ValueError(f"member {member} holds {_class_name(kind)} elements, not integers or floats")
    space = dataset.get_space()
    if space.get_simple_extent_type() != h5s.SIMPLE or not 1 <= space.get_simple_extent_ndims() <= 3:
        raise ValueError(f"member {member} is not an array of 1 to 3 dimensions")
    shape = space.shape
    if layout == h5d.CONTIGUOUS:
        return dataset.get_storage_size(), 0
    chunk = plist.get_chunk()
    elements, per_chunk = _product(shape), _product(chunk)
    if per_chunk < min(elements, MIN_CHUNK):
        raise ValueError(f"member {member} has chunks of {chunk}, smaller than a .clw writes")
    check_chunks(dataset, path, member, inflate=False)
    return dataset.get_storage_size(), _product(-(-n // c) for n, c in zip(shape, chunk))


def check_chunks(dataset, path, member, offsets=None, inflate=True) -> None:
    """Refuse (``ValueError``) a chunk of a chunked ``dataset`` (its low-level id) in the file at ``path``, of those
    at ``offsets`` (each chunk's first element; None: every chunk), that its compressing filter would decode past
    the chunk's bytes: HDF5's deflate filter grows its buffer as far as the stream goes (its stream decompressed
    here to the chunk's bytes and no further, kept nowhere: :func:`.loaders.inflate.inflated`), hdf5plugin's
    Zstandard and Blosc allocate what their header states (:func:`.loaders.inflate.check_stated`).  Without
    ``inflate`` (a ``.clw`` opened: its prefix reads must not pay for the whole file) a deflate chunk is weighed by its
    stored size alone: more than zlib's bound for the chunk's bytes (:data:`DEFLATE_SLACK`) is no stream a writer
    makes, and a stream within it inflates at most 1032 times (deflate's largest ratio), a few hundred MB for a
    ``.clw``'s largest chunks (docs/known-gaps.md §15, bomb29)."""
    import zlib

    from .loaders.inflate import HEADER, check_stated, inflated

    plist = dataset.get_create_plist()
    codes = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
    if not {DEFLATE, LZF, *STATED} & set(codes):
        return
    most = _product(plist.get_chunk()) * dataset.get_type().get_size()
    buffer = plist.get_filter_by_id(LZF)[1][2:3] if LZF in codes else ()
    if buffer and buffer[0] > most:  # h5py's lzf decoder allocates it first (0: the stored size)
        raise ValueError(f"member {member}: its lzf filter states a buffer of {buffer[0]:,} bytes, more than its "
                         f"chunk's {most:,}")
    stored = []
    if offsets is None:
        dataset.chunk_iter(stored.append)
    else:
        stored = [dataset.get_chunk_info_by_coord(tuple(offset)) for offset in offsets]
    with open(path, "rb") as fh:
        for info in stored:
            if info.byte_offset is None:  # not written: the fill value
                continue
            size = info.size
            for i in reversed(range(len(codes))):  # the filters in the order they decode
                if info.filter_mask >> i & 1:  # skipped for this chunk
                    continue
                if codes[i] == FLETCHER32:  # its checksum, the last 4 bytes, checked by HDF5
                    size -= 4
                    continue
                fh.seek(info.byte_offset)
                try:
                    if codes[i] == DEFLATE and not inflate:
                        if size > most + (most >> DEFLATE_SLACK) + 64:
                            raise ValueError(f"a deflate chunk is stored in {size:,} bytes, more than the {most:,} "
                                             "bytes it holds take compressed")
                    elif codes[i] == DEFLATE:
                        inflated(fh.read(size), zlib.decompressobj, None, most, "a deflate chunk")
                    elif codes[i] == LZF and size > most:
                        raise ValueError(f"an lzf chunk is stored in {size:,} bytes, more than the {most:,} bytes it "
                                         "holds (lzf stores no chunk that it does not shrink)")
                    elif codes[i] in STATED:
                        check_stated(STATED[codes[i]], fh.read(min(size, HEADER)), most)
                except (ValueError, zlib.error) as exc:
                    raise ValueError(f"member {member}, its chunk at {info.chunk_offset}: {exc}") from None
                break


def check_stored_inside(dataset, member) -> int:
    """The layout of a dataset (its low-level id), refused (``ValueError``) unless its data is in the file
    itself: not external raw storage (any file's bytes), not virtual (other datasets')."""
    from h5py import h5d

    plist = dataset.get_create_plist()
    layout = plist.get_layout()
    if layout not in (h5d.CONTIGUOUS, h5d.CHUNKED, h5d.COMPACT):
        raise ValueError(f"member {member} is a virtual dataset, whose data is other datasets'")
    if plist.get_external_count():
        raise ValueError(f"member {member} keeps its data in another file (external storage)")
    return layout


def check_filters_available(dataset, member) -> None:
    """Refuse (``ValueError``) a dataset (its low-level id) filtered by an HDF5 filter whose chunks
    :func:`check_chunks` cannot weigh before they are decoded (not in :data:`BOUNDED`: scale-offset and N-bit allocate
    what their parameters say, hdf5plugin's LZ4, bitshuffle, bzip2, ... what their stream holds), or one that neither
    HDF5 nor hdf5plugin decodes here: its chunks would fail one by one as they are read, HDF5 looking for a plugin in
    its plugin folder for each."""
    import hdf5plugin  # noqa: F401  (registers its filters with HDF5)
    from h5py import h5z

    plist = dataset.get_create_plist()
    for i in range(plist.get_nfilters()):
        code, _, _, label = plist.get_filter(i)
        label = label.decode(errors="replace") or BOUNDED.get(code, "unnamed")
        if code not in BOUNDED:
            raise ValueError(f"member {member} is filtered by {label!r} (id {code}), whose chunks clwave cannot "
                             "weigh before they are decoded")
        if not h5z.filter_avail(code):
            raise ValueError(f"member {member} is filtered by {label!r} (id {code}), which neither HDF5 nor "
                             "hdf5plugin decodes here")


def _check_attributes(obj, member, max_bytes):
    """Refuse more than :data:`MAX_ATTRIBUTES` attributes, or one larger than ``max_bytes``, or not of
    numbers or strings (read by their headers: no value is read)."""
    from h5py import h5a, h5t

    count = h5a.get_num_attrs(obj)
    if count > MAX_ATTRIBUTES:
        raise ValueError(f"member {member} has {count} attributes, more than a .clw writes")
    for i in range(count):
        attr = h5a.open(obj, index=i)
        kind = attr.get_type().get_class()
        if kind not in (h5t.INTEGER, h5t.FLOAT, h5t.STRING) or attr.get_storage_size() > max_bytes:
            raise ValueError(f"member {member} has an attribute {attr.name.decode(errors='replace')!r} of "
                             f"{_class_name(kind)} type and {attr.get_storage_size():,} bytes, not numbers or a "
                             f"string of at most {max_bytes:,}")


def _class_name(kind) -> str:
    from h5py import h5t

    names = {h5t.INTEGER: "integer", h5t.FLOAT: "float", h5t.STRING: "string", h5t.COMPOUND: "compound",
             h5t.REFERENCE: "reference", h5t.VLEN: "variable-length", h5t.ENUM: "enumerated", h5t.OPAQUE: "opaque",
             h5t.ARRAY: "array", h5t.BITFIELD: "bitfield", h5t.TIME: "time"}
    return names.get(kind, f"HDF5 class {kind}")


def _product(values) -> int:
    total = 1
    for v in values:
        total *= int(v)
    return total
