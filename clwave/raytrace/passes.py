"""Bigger than the device (docs/raytracing.md §6): the bricks beyond the device in a scratch file
(:class:`Spill`), the regions of bricks a render uploads one at a time, in the order every ray meets them
(:func:`planned`, :func:`passes`, :func:`ray_order`), and what each ray carries from one to the next
(:func:`carried`)."""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref

import numpy as np
import pyopencl.array as cla
from pyopencl import cltypes

from ..device.constants import BRICK
from ..device.kernels import zeros
from ..device.memory import format_size, parse_size, return_freed
from ..errors import DeviceMemoryError, OutputError
from ..model.geometry import view_in_fine


class Spill:
    """Pool elements (float4) that do not fit the device, in an unnamed scratch file in the temporary folder
    (``TMPDIR``): they cost the process no memory, the OS keeps what fits in free memory in its cache, and the
    file goes with the tracer (docs/raytracing.md §6).  Raises :class:`OutputError` when the folder has no room."""

    def __init__(self, elements: int):
        self.nbytes, folder = 16 * elements, tempfile.gettempdir()
        free = shutil.disk_usage(folder).free
        if self.nbytes > free:
            raise OutputError(f"the {format_size(self.nbytes)} of bricks beyond the device need that much room in "
                              f"{folder}, which has {format_size(free)}; free space there, or set TMPDIR to a "
                              f"folder on a larger disk")
        self.folder = folder
        self.file = tempfile.TemporaryFile(dir=folder, prefix="clwave-bricks-")
        weakref.finalize(self, self.file.close)  # closed (and so gone) with the pool

    def write(self, first: int, values: np.ndarray):
        """Elements ``first ..`` from ``values`` ((n, 4) float32)."""
        self._io(os.pwrite, first, np.ascontiguousarray(values, np.float32))

    def read_into(self, first: int, out: np.ndarray):
        """Elements ``first .. first + len(out)`` into ``out`` ((n, 4) float32, contiguous)."""
        self._io(lambda fd, view, at: os.preadv(fd, [view], at), first, out)

    def _io(self, call, first, arr):
        view, done = memoryview(arr).cast("B"), 0
        try:
            while done < len(view):
                moved = call(self.file.fileno(), view[done:], 16 * first + done)
                if moved <= 0:
                    raise OSError(0, "the scratch file ended early")
                done += moved
        except OSError as exc:
            raise OutputError(f"the scratch file of the bricks beyond the device in {self.folder} failed: "
                              f"{exc.strerror or exc}; free space there, or set TMPDIR to a folder on a larger "
                              f"disk") from None


def ray_order(index, eye, direction, perspective: bool) -> tuple:
    """Sort key of the region at ``index`` (z, y, x) of a grid of boxes: sorted by it, regions come in the order
    every ray meets them (docs/raytracing.md §6).  ``eye``: the grid index holding the eye (perspective, any
    real number); ``direction``: the rays' direction (z, y, x) (orthographic).  Along a ray the distance of its
    region from the eye's, or the index times the direction's sign, never decreases on any axis, so two regions
    one ray meets are ordered alike by every axis' key."""
    index = np.asarray(index, float)
    return tuple(np.abs(index - eye) if perspective else index * np.sign(direction))


def _region_sums(sizes, c) -> np.ndarray:
    """Sums of ``sizes`` over regions of c^3 cells (the last ones cut by the array's end)."""
    padded = np.pad(sizes, [(0, -n % c) for n in sizes.shape])
    Z, Y, X = (n // c for n in padded.shape)
    return padded.reshape(Z, c, Y, c, X, c).sum(axis=(1, 3, 5))


def on_device(pool_bytes: int, per_image: int, at) -> int:
    """Device memory a render in one pass over bricks kept on the device needs: the pool, the image's buffers
    (``per_image``) and the detail ``at``'s block bounds."""
    return pool_bytes + 2 * at.block_bound.nbytes + per_image


def passes(tracer, view, scale, offset, per_image, at, every=False) -> list:
    """The bricks of ``tracer`` in the scratch file as regions of c^3 bricks that fit the device one at a time, in
    an order every ray meets them in: ``[(slots, lo, hi)]`` with the region's box in grid-0 fine coordinates (x, y, z);
    ``every``: regions without bricks too (a transfer function that shows the field's 0 there, docs/raytracing.md §10).

    Along every ray the distance of its region index from the eye's (perspective), or the index times the
    direction's sign (orthographic), never decreases per axis, so sorting regions by those keys
    (lexicographically) orders them along every ray alike (docs/raytracing.md §6).
    """
    f = tracer.bricks
    fixed = per_image + 2 * at.block_bound.nbytes + 4 * int(np.prod(f.shape)) + 256
    room = min(tracer.budget.total - fixed, tracer.budget.max_alloc)
    sizes = np.zeros(f.shape, np.int64)  # a brick's pool and its tables (frames, boxes, lattices)
    sizes[tuple((f.bricks[at.slots] - f.origin).T)] = f.slot_bytes()[at.slots] + 16 + 32 * len(tracer.orders)
    if room < sizes.max():  # the least budget that works, by the rules a tracer made with it follows: passes, or
        least, what = fixed + sizes.max(), "its largest brick and this image's buffers"
        if f.device_from is not None and parse_size(format_size(least)) >= f.device_from:  # (as the message rounds)
            # at that much build keeps the pool on the device, where it must fit beside this image's buffers
            least = max(f.device_from, on_device(f.device_pool_bytes, per_image, at))
            what = "its bricks, which stay on the device at that much, and this image's buffers"
        raise DeviceMemoryError(
            f"ray tracing this volume needs at least {format_size(least)} of device memory ({what}) but "
            f"{format_size(tracer.budget.total)} are allowed; raise --device-memory (device_memory=) or render a "
            f"smaller image")
    c = max(k for k in range(1, max(f.shape) + 1) if _region_sums(sizes, k).max() <= room)
    if not f.given_back:  # the set-up's freed memory, kept by the C library, back to the system before the first
        return_freed()  # region comes; later renders leave little to give back (docs/raytracing.md §6)
        f.given_back = True
    sums = _region_sums(sizes, c)
    eye, direction = view_in_fine(view, scale, offset)
    eye_region = np.floor((eye / BRICK - f.origin) / c)
    regions = []
    for r in np.argwhere((sums > 0) | every):
        inside = np.all(((f.bricks[at.slots] - f.origin) // c) == r, axis=1)
        lo = (f.origin + r * c) * BRICK
        regions.append((ray_order(r, eye_region, direction, view.perspective), at.slots[inside],
                        lo[::-1], (lo + c * BRICK)[::-1]))
    regions.sort(key=lambda item: item[0])
    return [(slots, lo, hi) for _, slots, lo, hi in regions]


def planned(tracer, view, scale, offset, per_image, at, every=False) -> list | None:
    """A render's passes: ``None`` for one over whole rays (raising :class:`DeviceMemoryError` where the image's
    buffers, ``per_image``, do not fit beside a pool on the device), else ``[(slots or None for all, lo, hi)]``
    (x, y, z): the scratch file's regions (:func:`passes`), or a cluster part's region as one pass."""
    if tracer.field != "bspline":  # the wavelet field's tables are on the device whole
        return None
    f = tracer.bricks
    if not f.resident:
        return passes(tracer, view, scale, offset, per_image, at, every)
    need = on_device(f.pool_bytes, per_image, at)
    if need > tracer.budget.total:
        H, W = view.size
        raise DeviceMemoryError(
            f"a {H}x{W} ray-traced image needs {format_size(per_image)} of device memory beside the "
            f"{format_size(f.pool_bytes)} of bricks, {format_size(need)} in all, but "
            f"{format_size(tracer.budget.total)} are allowed; render a smaller image, or make the tracer with "
            f"a smaller device_memory= (--device-memory) so that its bricks render in passes")
    if tracer.region is None:
        return None
    lo = np.append(tracer.region[0], f.origin[1:]) * BRICK
    return [(None, lo[::-1], np.append(tracer.region[1], f.origin[1:] + f.shape[1:])[::-1] * BRICK)]


REAL4 = {np.float32: cltypes.float4, np.float64: cltypes.double4}


def carried(q, shape, real, tol, absorption, several) -> tuple:
    """What each ray of a ``shape`` (H, W) image carries from one pass to the next where there are ``several``
    (docs/raytracing.md §6): its colour and transmittance, the error budgets left, where it resumes; else
    one-element placeholders."""
    if not several:
        return zeros(q, 1, REAL4[real]), zeros(q, 1, REAL4[real]), zeros(q, 1, real)
    ledger_start = (tol / 2, 0, 0, 0) if not absorption else (tol / 4, tol * 3 / 8, 0, 0)
    carry = cla.to_device(q, np.tile(np.array((0, 0, 0, 0 if not absorption else 1), real), (*shape, 1)))
    ledger = cla.to_device(q, np.tile(np.array(ledger_start, real), (*shape, 1)))
    return carry, ledger, cla.to_device(q, np.full(shape, -np.inf, real))
