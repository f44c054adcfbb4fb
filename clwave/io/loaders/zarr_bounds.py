"""Zarr's decompressors bounded by the chunk's size (docs/known-gaps.md §15, bomb29): numcodecs' zlib, gzip, bzip2 and
LZMA decode a chunk whole whatever it inflates to, and its Blosc, Zstandard and LZ4 allocate the size their stream's
header states, so a chunk of a few kilobytes could take gigabytes.  Within :func:`bounded` a store is opened with each
of those replaced: a stream decompressed to the chunk's bytes and refused (ValueError) a byte past them
(:func:`.inflate.inflated`), a stated size refused above them before anything is decoded; zarr's own (v3) codecs by
its codec registry, a v2 array's numcodecs compressor by its codec pipeline."""

from __future__ import annotations

import asyncio
import bz2
import lzma
import math
import zlib
from contextlib import contextmanager
from dataclasses import replace
from functools import partial

import zarr
from zarr.codecs import BloscCodec, GzipCodec, ZstdCodec
from zarr.codecs._v2 import V2Codec
from zarr.core.codec_pipeline import BatchedCodecPipeline

from .inflate import GZIP, HEADER, check_stated, inflated

#: bytes a v2 chunk's element may take between its filters (they may widen it) and its compressor
FILTERED_ITEM = 8


def stream(codec):
    """:func:`.inflate.decompressed`'s ``(new, magic)`` for a numcodecs compressor ``codec`` that decodes a stream
    whole (None for another)."""
    return {"zlib": (zlib.decompressobj, None), "gzip": GZIP, "bz2": (bz2.BZ2Decompressor, None),
            "lzma": (partial(lzma.LZMADecompressor, format=getattr(codec, "format", None),
                             filters=getattr(codec, "filters", None)), None)}.get(codec.codec_id)


def _head(chunk_bytes) -> bytes:
    return bytes(chunk_bytes.as_numpy_array()[:HEADER])


def _chunk_bytes(chunk_spec, per_item=None) -> int:
    return math.prod(chunk_spec.shape) * (per_item or chunk_spec.dtype.to_native_dtype().itemsize)


class BoundedV2(V2Codec):
    """A v2 array's decoding, its numcodecs compressor's stream decompressed to the chunk's size at the most."""

    async def _decode_single(self, chunk_bytes, chunk_spec):
        if self.compressor is None:
            return await super()._decode_single(chunk_bytes, chunk_spec)
        most = _chunk_bytes(chunk_spec, FILTERED_ITEM if self.filters else None)
        codec = stream(self.compressor)
        if codec is None:
            check_stated(self.compressor.codec_id, _head(chunk_bytes), most)
            return await super()._decode_single(chunk_bytes, chunk_spec)
        out = await asyncio.to_thread(inflated, chunk_bytes.to_bytes(), *codec, most,
                                      f"a {self.compressor.codec_id} chunk")
        return await replace(self, compressor=None)._decode_single(chunk_spec.prototype.buffer.from_bytes(out),
                                                                   chunk_spec)


class BoundedPipeline(BatchedCodecPipeline):
    """zarr's codec pipeline, a v2 array's decoding by :class:`BoundedV2`."""

    @classmethod
    def from_codecs(cls, codecs, *, batch_size=None):
        codecs = [BoundedV2(filters=c.filters, compressor=c.compressor) if type(c) is V2Codec else c for c in codecs]
        return super().from_codecs(codecs, batch_size=batch_size)


class BoundedGzip(GzipCodec):
    def _decode_sync(self, chunk_bytes, chunk_spec):
        out = inflated(chunk_bytes.to_bytes(), *GZIP, _chunk_bytes(chunk_spec), "a gzip chunk")
        return chunk_spec.prototype.buffer.from_bytes(out)


class BoundedZstd(ZstdCodec):
    def _decode_sync(self, chunk_bytes, chunk_spec):
        check_stated("zstd", _head(chunk_bytes), _chunk_bytes(chunk_spec))
        return super()._decode_sync(chunk_bytes, chunk_spec)


class BoundedBlosc(BloscCodec):
    def _decode_sync(self, chunk_bytes, chunk_spec):
        check_stated("blosc", _head(chunk_bytes), _chunk_bytes(chunk_spec))
        return super()._decode_sync(chunk_bytes, chunk_spec)


V3_CODECS = {"gzip": BoundedGzip, "zstd": BoundedZstd, "blosc": BoundedBlosc}
for _name, _codec in V3_CODECS.items():
    zarr.registry.register_codec(_name, _codec)
zarr.registry.register_pipeline(BoundedPipeline)


@contextmanager
def bounded():
    """Arrays opened within it decode through the bounded codecs (theirs from then on: zarr builds an array's codecs
    when it opens it)."""
    with zarr.config.set({"codec_pipeline.path": f"{__name__}.BoundedPipeline"}
                         | {f"codecs.{name}": f"{__name__}.{codec.__name__}" for name, codec in V3_CODECS.items()}):
        yield
