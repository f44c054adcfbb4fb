"""Compressed streams decompressed a piece at a time, never past a bound: a reader gives the size its header
declares, so that a few kilobytes that inflate to gigabytes (a decompression bomb) are refused by the byte past it,
not after they are held (docs/coordinates.md §4, untrusted input)."""

from __future__ import annotations

import zlib

#: compressed bytes read, and decompressed bytes made, at a time
PIECE = 1 << 20
#: the first bytes of a gzip stream (of each of its members)
GZIP_MAGIC = b"\x1f\x8b"
#: :func:`decompressed`'s ``new`` and ``magic`` for a gzip stream: a decompressor a member
GZIP = (lambda: zlib.decompressobj(zlib.MAX_WBITS | 16), GZIP_MAGIC)


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
