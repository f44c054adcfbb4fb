"""Compressed streams decompressed a piece at a time, never past a bound: a reader gives the size its header
declares, so that a few kilobytes that inflate to gigabytes (a decompression bomb) are refused by the byte past it,
not after they are held (docs/coordinates.md §4, untrusted input)."""

from __future__ import annotations

import io
import zlib

#: compressed bytes read, and decompressed bytes made, at a time
PIECE = 1 << 20
#: the first bytes of a gzip stream (of each of its members)
GZIP_MAGIC = b"\x1f\x8b"
#: :func:`decompressed`'s ``new`` and ``magic`` for a gzip stream: a decompressor a member
GZIP = (lambda: zlib.decompressobj(zlib.MAX_WBITS | 16), GZIP_MAGIC)
#: the first bytes of a Zstandard frame
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
#: bytes of a chunk's header that :func:`stated_size` reads (a Zstandard frame's, the longest, takes 18)
HEADER = 32


def decompressed(source, new, magic, most):
    """The compressed stream read from the file ``source``, decompressed a piece at a time by decompressors that
    ``new`` makes (zlib's or bz2's), ``most`` bytes at the most: one member after another while the bytes after one
    start with ``magic`` (others, as zero padding, end it; no ``magic``: one member); it ends where the file does
    (a stream cut short: the caller weighs what came)."""
    decompressor, data = new(), source.read(PIECE)
    while most > 0:
        room = min(most, PIECE)
        piece = decompressor.decompress(data, room)
        most -= len(piece)
        if piece:
            yield piece
        if decompressor.eof:
            data = decompressor.unused_data
            if magic and len(data) < len(magic):
                data += source.read(PIECE)
            if not magic or not data.startswith(magic):
                return
            decompressor = new()
            continue
        data = getattr(decompressor, "unconsumed_tail", b"")  # bzip2 keeps its own
        if not data and len(piece) < room and not (data := source.read(PIECE)):
            return


def inflated(data, new, magic, most, what) -> bytes:
    """``data`` (a compressed stream in memory) decompressed as :func:`decompressed` does, ``most`` bytes at the
    most: one that holds more is refused (ValueError naming ``what``) by the byte past them, never held."""
    out = b"".join(decompressed(io.BytesIO(data), new, magic, most + 1))
    if len(out) > most:
        raise ValueError(f"{what} inflates past the {most:,} bytes it holds: it is not what it says (a decompression "
                         "bomb)")
    return out


def stated_size(codec_id, data) -> int | None:
    """The decoded size that the header of a chunk ``data`` (bytes) compressed by ``codec_id`` states: Blosc's
    ``nbytes``, a Zstandard frame's content size (-1 where the frame states none), LZ4's (numcodecs') size prefix;
    None for another codec."""
    if codec_id == "blosc":
        return int.from_bytes(data[4:8], "little")
    if codec_id == "lz4":
        return int.from_bytes(data[:4], "little")
    if codec_id != "zstd":
        return None
    if len(data) < 5 or data[:4] != ZSTD_MAGIC:
        return -1
    descriptor = data[4]
    single = descriptor >> 5 & 1
    size = (single, 2, 4, 8)[descriptor >> 6]
    start = 5 + (1 - single) + (0, 1, 2, 4)[descriptor & 3]
    field = data[start:start + size]
    if not size or len(field) < size:
        return -1
    return int.from_bytes(field, "little") + (256 if size == 2 else 0)


def check_stated(codec_id, head, most):
    """Refuse (ValueError) a chunk whose header (its first :data:`HEADER` bytes, ``head``) states more than ``most``
    bytes, or a Zstandard frame that states none (numcodecs would grow its buffer as it decodes)."""
    size = stated_size(codec_id, head)
    if size is not None and not 0 <= size <= most:
        said = "does not state its size" if size < 0 else f"declares {size:,} bytes"
        raise ValueError(f"a {codec_id} chunk {said}, where its chunk holds {most:,}: it is not what it says (a "
                         f"decompression bomb)")
