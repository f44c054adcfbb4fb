"""ContentMask: which voxels of the source volume are non-zero, one bit each (docs/raytracing.md §4).

The ray tracer zeroes the fine B-spline coefficients of empty voxels and renders the cells no non-zero
voxel reaches as empty; it reads the mask a box at a time (a slab of bricks, a brick row).  Packed along x
(``np.packbits``), a 1024³ volume's mask takes 128 MiB, where a byte a voxel took 1 GiB.
"""

from __future__ import annotations

import numpy as np


class ContentMask:
    """The non-zero voxels of a volume of ``shape`` (nz, ny, nx), as bits packed along x."""

    def __init__(self, shape, bits: np.ndarray | None = None):
        self.shape = tuple(int(n) for n in shape)
        packed = (*self.shape[:2], -(-self.shape[2] // 8))
        self.bits = np.zeros(packed, np.uint8) if bits is None else bits
        if self.bits.shape != packed or self.bits.dtype != np.uint8:
            raise ValueError(f"packed bits of shape {self.bits.shape} and type {self.bits.dtype} do not make "
                             f"a mask of shape {self.shape}")

    @classmethod
    def of(cls, mask) -> "ContentMask":
        """The mask of a (nz, ny, nx) array: its non-zero elements."""
        mask = np.asarray(mask)
        return cls(mask.shape, np.packbits(mask != 0, axis=2))

    def put(self, start, block):
        """Set the box at ``start`` (z, y, x) to ``block`` (inside the volume)."""
        block = np.asarray(block) != 0
        stop = np.add(start, block.shape)
        if np.any(np.asarray(start) < 0) or np.any(stop > self.shape):
            raise ValueError(f"a block of shape {block.shape} at {tuple(start)} is outside the mask {self.shape}")
        (z0, y0, x0), (z1, y1, x1) = start, stop
        first, last = x0 // 8, -(-x1 // 8)  # the bytes the box touches: unpacked, set, packed again
        rows = np.unpackbits(self.bits[z0:z1, y0:y1, first:last], axis=2)
        rows[..., x0 - 8 * first:x1 - 8 * first] = block
        self.bits[z0:z1, y0:y1, first:last] = np.packbits(rows, axis=2)

    def box(self, start, shape) -> np.ndarray:
        """Bool (``shape``): whether voxel ``start + index`` is non-zero; False beyond the volume."""
        out = np.zeros(tuple(int(n) for n in shape), bool)
        lo = np.maximum(start, 0)
        hi = np.minimum(np.add(start, shape), self.shape)
        if np.all(hi > lo):
            (z0, y0, x0), (z1, y1, x1) = lo, hi
            first = x0 // 8
            rows = np.unpackbits(self.bits[z0:z1, y0:y1, first:-(-x1 // 8)], axis=2)
            out[tuple(slice(a - s, b - s) for a, b, s in zip(lo, hi, start))] = \
                rows[..., x0 - 8 * first:x1 - 8 * first].view(bool)
        return out

    def __array__(self, dtype=None, copy=None):
        """The whole mask, unpacked: for small volumes and tests."""
        if copy is False:
            raise ValueError("a ContentMask is packed: unpacking it copies")
        whole = self.box((0, 0, 0), self.shape)
        return whole if dtype is None else whole.astype(dtype)

