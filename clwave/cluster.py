"""Rendering on a Dask cluster (docs/raytracing.md §7, docs/splatting.md §7): parts of an image, each on a
worker that opens the model's ``.clw`` file itself and keeps its renderer for later views.  The cluster is
named as :mod:`clwave.schedulers` takes it.
"""

from __future__ import annotations

import threading

from .errors import InputError

#: per worker process: the renderers of the last few (file, options, part) asked for, set up once
_RENDERERS: dict = {}
_KEEP_RENDERERS = 4
_LOCK = threading.Lock()


def check_model_file(wv, what: str):
    """InputError unless ``wv`` was opened from a ``.clw`` file as it is there: the workers of a cluster open
    the file themselves (docs/raytracing.md §7); ``what`` names the rendering."""
    from .model.wavelet import check_model

    check_model(wv, what)
    if wv.source is None:
        raise InputError(f"{what} on a Dask cluster needs a model opened from a .clw file, as it is (its workers "
                         "open the file themselves): save it (wv.save) and render WaveletVolume.open(path)",
                         cli="--workers/--scheduler render the .clw file as it is: --threshold and --focus cannot "
                             "apply there; compress a model with them first")


def render_parts(client, task, source, parts, *args) -> list:
    """``task(renderer_of, part, *args)`` for each part, each part on a worker of its own (round robin), the
    results in the order of ``parts``.  ``renderer_of(make, device, device_memory, *key)`` on the worker gives
    the renderer ``make(model, cap)`` builds for this file, part, device, cap and ``key`` (the other options it
    depends on), kept there for later views; ``cap`` is its share of the device (:func:`worker_cap`) among the
    parts on that worker's machine."""
    from distributed.comm import get_address_host

    workers = sorted(client.nthreads())
    chosen = [workers[i % len(workers)] if workers else None for i in range(len(parts))]
    hosts = [get_address_host(w) if w else None for w in chosen]
    futures = [client.submit(_run_part, task, source, part, hosts.count(host), args, pure=False,
                             workers=None if worker is None else [worker])
               for part, worker, host in zip(parts, chosen, hosts)]
    return client.gather(futures)


def worker_cap(device, device_memory, sharing: int):
    """The device memory one of ``sharing`` workers on one machine plans for: at most ``device_memory`` and at
    most its share of the device, which they may all have picked (a CPU device is the machine's memory)."""
    if sharing <= 1:
        return device_memory
    from .device.context import ComputeContext
    from .device.memory import parse_cap

    total, cap = ComputeContext.get(device).info.global_mem, parse_cap(device_memory)
    return min(total if cap is None else cap, total // sharing)


def workers_of(client) -> int:
    """How many workers the cluster has (at least 1), asked of the scheduler: ``client.scheduler_info()`` may
    answer with the client's periodic refresh, which lists no workers (distributed 2026.8)."""
    return max(1, len(client.nthreads()))


def _run_part(task, source, part, sharing, args):
    def renderer_of(make, device, device_memory, *key):
        with _LOCK:  # a worker of several threads: one set-up at a time
            full = (task.__qualname__, source, part, device, device_memory, sharing, *key)
            if full not in _RENDERERS:
                from .model.wavelet import WaveletVolume

                while len(_RENDERERS) >= _KEEP_RENDERERS:
                    _RENDERERS.pop(next(iter(_RENDERERS)))
                _RENDERERS[full] = make(WaveletVolume.open(source[0], keep=source[1]),
                                        worker_cap(device, device_memory, sharing))
            return _RENDERERS[full]

    return task(renderer_of, part, *args)
