"""The host side of the host-kernel boundary: each kernel's arguments declared once, by name.

A :class:`Kernel` lists a kernel's arguments in the order of its OpenCL signature, each with
its type: a NumPy scalar type, a ``pyopencl.cltypes`` vector type (given any sequence of up to
its length, zero-padded), :data:`BUFFER`, or :data:`REAL` (the build's precision).
Launches name every argument (``KERNEL(ks, queue, (n,), None, n=n, first=0, ...)``), so a
renderer and the kernel's test call the same declaration and an argument cannot slip position.
Constants that both sides use come from :mod:`clwave.device.constants` as build defines.

A device's programs are shared by every renderer and thread; a launch sets its kernel's arguments and then enqueues,
so each thread launches kernel objects of its own (:class:`~clwave.device.programs.KernelSet`), and pyopencl's
generated kernels, which hold one, under the device's ``launch_lock`` (:class:`Locked`; docs/coordinates.md §4).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import numpy as np

from ..threads import checkpoint, drain

BUFFER = "buffer"  #: a ``pyopencl`` buffer, or an array whose ``.data`` is one
REAL = "real"      #: the kernel's ``real``: float32 or float64 by the build (``real_type=`` at launch)


class Kernel:
    """One kernel's name and its ``(argument name, type)`` pairs in signature order."""

    def __init__(self, name: str, *args: tuple):
        self.name = name
        self.args = tuple(args)
        self.names = tuple(a for a, _ in args)
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"{name}: an argument is declared twice")

    def __repr__(self):
        return f"Kernel({self.name}: {', '.join(self.names)})"

    def arguments(self, tables: Mapping | None = None, real_type=np.float32, **values) -> list:
        """The positional arguments from ``values`` by name; missing names are taken from
        ``tables`` (a mapping that may hold more), so a view's uploaded tables pass as one."""
        unknown = set(values) - set(self.names)
        if unknown:
            raise TypeError(f"{self.name} takes no argument {', '.join(sorted(unknown))}")
        out = []
        for name, kind in self.args:
            if name in values:
                value = values[name]
            elif tables is not None and name in tables:
                value = tables[name]
            else:
                raise TypeError(f"{self.name}: argument {name} is missing")
            if kind == BUFFER:
                out.append(getattr(value, "data", value))
            elif kind == REAL:
                out.append(np.dtype(real_type).type(value))
            elif isinstance(kind, np.dtype) and kind.fields:  # an OpenCL vector type (cltypes)
                out.append(_vector(kind, value))
            else:
                out.append(np.dtype(kind).type(value))
        return out

    def __call__(self, kernels, queue, global_size, local_size, tables: Mapping | None = None, real_type=np.float32,
                 **values):
        """Launch the kernel of this name from ``kernels`` (a :class:`~clwave.device.programs.KernelSet`: this
        thread's kernel object)."""
        args = self.arguments(tables, real_type, **values)
        return kernels[self.name](queue, global_size, local_size, *args)


class Locked:
    """One of pyopencl's generated kernels (element-wise, reduction, scan: ``ComputeContext.generated``), which
    holds one kernel object for every thread: each call under the device's ``launch_lock``."""

    def __init__(self, kernel, lock):
        self.kernel, self.lock = kernel, lock

    def __call__(self, *args, **kwargs):
        with self.lock:
            return self.kernel(*args, **kwargs)


def zeros(queue, shape, dtype, allocator=None):
    """``pyopencl.array.zeros``, filled by the queue (:func:`zero`)."""
    import pyopencl.array as cla

    return zero(queue, cla.empty(queue, shape, dtype, allocator=allocator))


def zero(queue, out):
    """``out`` (an array, or a slice of one) set to 0 by the queue (``enqueue_fill_buffer``) rather than by pyopencl's
    fill kernel, which every thread of the context shares without a lock; returns ``out``."""
    import pyopencl as cl

    if out.nbytes:
        pattern = np.zeros(math.gcd(16, out.offset, out.nbytes), np.uint8)  # the widest pattern that tiles it
        cl.enqueue_fill_buffer(queue, out.base_data, pattern, out.offset, out.nbytes)
    return out


LAUNCH_SECONDS = 0.2  #: what one launch of a long kernel aims at: Ctrl-C waits for the launch running


class Pace:
    """The rate (work per second) of the last band of one kernel's :func:`in_bands`, kept between calls,
    so that a call's first band is sized from it rather than grown from one step (each launch and
    wait costs a fraction of a millisecond, and small bands leave cores idle)."""

    def __init__(self):
        self.rate = None


def in_bands(queue, launch, total: int, step: int = 1, work=None, pace: Pace | None = None):
    """``launch(first, count)`` over consecutive bands of the items ``0 .. total``, the queue finished after
    each, so that Python takes a KeyboardInterrupt within about :data:`LAUNCH_SECONDS` however long the
    whole is (:func:`bands`, run to its end)."""
    drain(bands(queue, launch, total, step, work, pace))


def bands(queue, launch, total: int, step: int = 1, work=None, pace: Pace | None = None):
    """A generator of :func:`in_bands`' launches, yielding between two bands (a viewer's saved image takes turns
    with its tabs' frames there, docs/viewer.md §5).  Bands are whole multiples of ``step`` items (the last may be
    short), each sized from the rate of the last, at most twice its work (light items say little of the next ones);
    the first from ``pace`` (the rate of the last call) for half of :data:`LAUNCH_SECONDS` (other work, a weaker
    guide), or one step.  ``work`` is the cost of the items: a number per item, or their cumulative cost
    (``total + 1`` non-decreasing numbers from 0) where it varies (a tile's records); default 1 each."""
    uniform = work is None or np.isscalar(work)

    def fit(first, budget):  # how many items from ``first`` cost at most ``budget``, in whole steps
        n = budget / (work or 1) if uniform else np.searchsorted(work, work[first] + budget, side="right") - 1 - first
        return max(step, int(n) // step * step)

    done = 0
    items = step if pace is None or not pace.rate else fit(0, pace.rate * LAUNCH_SECONDS / 2)
    while done < total:
        checkpoint()  # a thread given a stop (threads.stop_on) gives up here
        count = min(items, total - done)
        start = time.perf_counter()
        launch(done, count)
        queue.finish()
        spent = max(count * (work or 1) if uniform else work[done + count] - work[done], 1e-9)
        rate = spent / max(time.perf_counter() - start, 1e-6)
        if pace is not None:
            pace.rate = rate
        done += count
        items = fit(done, min(2 * spent, rate * LAUNCH_SECONDS)) if done < total else 0
        if done < total:
            yield


def in_row_bands(queue, launch, global_size, local_size):
    """``launch(global_size, first_row)`` of a 2-D range over :func:`in_bands` of its rows (axis 1, whole
    work-groups of rows).  A band's kernel adds ``first_row`` to its row itself: launched with a global offset
    instead, PoCL would compile each kernel twice, for the first band and for the others (docs/benchmarks.md §22)."""
    drain(row_bands(queue, launch, global_size, local_size))


def row_bands(queue, launch, global_size, local_size):
    """:func:`in_row_bands` as a generator yielding between two bands (:func:`bands`)."""
    return bands(queue, lambda row, rows: launch((global_size[0], rows), row), global_size[1], local_size[1])


def _vector(kind: np.dtype, value):
    """An OpenCL vector of ``kind`` from a sequence of at most its length (zero-padded), or as given."""
    if getattr(value, "dtype", None) == kind:
        return value
    size, real = len(kind.names), kind.fields["s0"][0].kind == "f"
    items = [float(v) if real else int(v) for v in value]
    if len(items) > size:
        raise TypeError(f"{len(items)} values do not fit a {size}-vector")
    return np.array(tuple(items + [0] * (size - len(items))), dtype=kind)  # 0-d, as pyopencl.cltypes makes
