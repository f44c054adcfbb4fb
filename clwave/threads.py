"""Host threads: one process-wide pool, one thread per core the process may use, for the NumPy and
SciPy work that releases the GIL (per-channel transforms, classification chunks, footprint textures).
Threads are started once, not per call (starting them cost more than a small view's FFTs).  Work that another
thread may give up (a ray tracer's set-up, a file's reading) stops with :class:`Abandoned` (:func:`checkpoint`)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from functools import lru_cache, wraps


class Abandoned(Exception):
    """Work given up from another thread: a ray tracer's set-up after its ``abandon`` event was set
    (:func:`checkpoint`), a file's reading stopped (the viewer's: its reader, and the whole model that the shaded views
    wait for), or a staged tracer's refinement after its full stage was given up (``StagedTracer.abandon``)."""


_thread = threading.local()  # .stop: the event of stop_on, where the thread has one


def stop_on(event: threading.Event):
    """This thread's work gives up at its next :func:`checkpoint` once ``event`` is set: a thread that is not the
    main one (a viewer's render and build threads) takes no KeyboardInterrupt, and its stop then ends the work under
    way within a kernel launch (:func:`clwave.device.kernels.in_bands`) or a slab of a set-up, not at its end
    (docs/viewer.md §1)."""
    _thread.stop = event


def checkpoint(abandon=None) -> None:
    """:class:`Abandoned` once ``abandon`` (a ``threading.Event``, or None) or this thread's :func:`stop_on` event is
    set: called between two units of work that another thread may give up (a ray tracer's set-up, docs/raytracing.md
    §8; a kernel's bands of launches)."""
    for event in (abandon, getattr(_thread, "stop", None)):
        if event is not None and event.is_set():
            raise Abandoned("given up from another thread between two units of work")


def drain(stages):
    """Run a generator of stages (one that yields between units of work another may take turns with) to its end;
    what it returns."""
    while True:
        try:
            next(stages)
        except StopIteration as end:
            return end.value


def in_turns(lock, stages):
    """A generator of ``stages``' stages with ``lock`` held for each, not between two (where others take their
    turns); returns what ``stages`` returns."""
    while True:
        with lock:
            try:
                next(stages)
            except StopIteration as end:
                return end.value
        yield


def one_at_a_time(method):
    """``method`` run under its object's ``lock``, a renderer's device's (``ComputeContext.lock``): renderers used
    from several threads at once render one view at a time on a device, each call waiting for the one under way
    (a renderer's buffers and pyopencl's own array kernels are shared; docs/coordinates.md §4)."""
    @wraps(method)
    def locked(self, *args, **kwargs):
        with self.lock:
            return method(self, *args, **kwargs)
    return locked


class MadeOnce:
    """Objects made once each, by key: the first thread to ask for a key makes it (``make()``) while any other that
    asks for that key waits for it, not for the making of other keys (a viewer's render thread takes a model's
    splat renderer while its build thread makes the ray tracer).  Pickles empty: what it holds is this process's."""

    def __init__(self):
        self.made, self._locks, self._lock = {}, {}, threading.Lock()

    def get(self, key, make):
        with self._lock:  # held a moment: the key's own lock, made on first use
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self.made:
                self.made[key] = make()
            return self.made[key]

    def clear(self):
        self.made.clear()

    def __len__(self):
        return len(self.made)

    def __reduce__(self):
        return MadeOnce, ()


def cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


@lru_cache(maxsize=1)
def _pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(cores(), thread_name_prefix="clwave")


if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: a pool of its own
    os.register_at_fork(after_in_child=_pool.cache_clear)


def thread_map(work, items) -> list:
    """``[work(item) for item in items]``, in the pool when there is more than one item and core.

    ``work`` must not itself wait on the pool."""
    items = list(items)
    if len(items) < 2 or cores() < 2:
        return [work(item) for item in items]
    return list(_pool().map(work, items))


def background(work, *args, **kwargs) -> Future:
    """``work(*args, **kwargs)`` started in the pool while the caller goes on; ``.result()`` waits for it.

    ``work`` must not itself wait on the pool."""
    return _pool().submit(work, *args, **kwargs)
