"""Dask as the engine of chunked work (docs/chunked.md §5): the scheduler a user names, and the results of
many block tasks streamed back in their order.  The model and the
file format build on this module; rendering on a cluster is :mod:`clwave.cluster`.

``scheduler`` everywhere takes: None (threads of this process: a ``distributed.LocalCluster`` without
processes), an int N (a local cluster of N worker processes), an address ``tcp://HOST:PORT`` of a
running scheduler, or a ``distributed.Client``.
"""

from __future__ import annotations

import contextlib
import logging
import warnings

from .errors import InputError, WorkerLostError
from .io.progress import progress
from .threads import cores

CONNECT_TIMEOUT = "10s"


def check_scheduler(scheduler):
    """``scheduler`` if it is one of the forms this module takes, else an InputError naming them."""
    if scheduler is None or _is_client(scheduler):
        return scheduler
    if isinstance(scheduler, int) and not isinstance(scheduler, bool):
        if not 1 <= scheduler <= 4 * cores() + 64:
            raise InputError(f"workers={scheduler} must be a number of local worker processes from 1 to "
                             f"{4 * cores() + 64}", cli=f"--workers {scheduler} must be from 1 to {4 * cores() + 64}")
        return scheduler
    if isinstance(scheduler, str) and "://" in scheduler:
        return scheduler
    raise InputError(f"scheduler={scheduler!r} is not a Dask scheduler: give None (threads), a number of local "
                     "worker processes, an address tcp://HOST:PORT or a distributed.Client",
                     cli=f"--scheduler {scheduler} is not an address: give tcp://HOST:PORT of a running "
                         "Dask scheduler")


@contextlib.contextmanager
def client_for(scheduler=None):
    """A ``distributed.Client`` for ``scheduler`` (see the module), closed on leaving unless it was given.  A task
    whose workers all died running it (Dask gives up after a few, ``KilledWorker``) ends the work with a
    :class:`WorkerLostError` line rather than Dask's exception, which the command line took for a bug of clwave."""
    from distributed import KilledWorker

    scheduler = check_scheduler(scheduler)
    with _client(scheduler) as client:
        try:
            yield client
        except KilledWorker:
            why = ("the Dask workers died running one of this work's tasks, each worker that took it in turn (most "
                   "often out of memory: a worker is stopped at 95 % of its memory limit); ")
            if isinstance(scheduler, int):  # a local cluster of this process's (its workers' logs silenced)
                raise WorkerLostError(why + "give fewer workers (each has a share of the memory) or smaller chunks "
                                            "(load(chunks=))",
                                      cli=why + "give fewer --workers (each has a share of the memory) or a smaller "
                                                "--chunks edge") from None
            raise WorkerLostError(why + "see the workers' logs, and give smaller chunks (load(chunks=)) or workers "
                                        "with more memory",
                                  cli=why + "see the workers' logs, and give a smaller --chunks edge or workers with "
                                            "more memory") from None


@contextlib.contextmanager
def _client(scheduler):
    """The client of a checked ``scheduler``: the one given, one connected to an address, or a local cluster's."""
    if _is_client(scheduler):
        yield scheduler
        return
    from distributed import Client, LocalCluster

    for name in ("distributed", "tornado"):  # their chatter (and a failed task's log: it is raised here) is not ours
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if isinstance(scheduler, str):
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"no Dask scheduler answers at {scheduler} ({type(exc).__name__}); start one "
                             "(`dask scheduler`, then `dask worker ADDRESS`) or check the address",
                             cli=f"--scheduler {scheduler}: no Dask scheduler answers there; start one "
                                 "(`dask scheduler`, then `dask worker ADDRESS`) or check the address") from None
        with client:
            try:  # a scheduler without workers takes the tasks and runs none: the work would wait for ever
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
            except TimeoutError:
                raise InputError(f"the Dask scheduler at {scheduler} has no workers (none joined within "
                                 f"{CONNECT_TIMEOUT}); start some (`dask worker {scheduler}`)",
                                 cli=f"--scheduler {scheduler}: the Dask scheduler there has no workers (none joined "
                                     f"within {CONNECT_TIMEOUT}); start some (`dask worker {scheduler}`)") from None
            yield client
        return
    if scheduler is None:
        cluster = LocalCluster(processes=False, n_workers=1, threads_per_worker=cores(),
                               dashboard_address=":0", memory_limit=0)
    else:  # silence_logs: the worker processes' logs too (a task cancelled by a SIGTERM is one such line)
        cluster = LocalCluster(n_workers=scheduler, threads_per_worker=1, dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
    with cluster, Client(cluster) as client:
        yield client


def _is_client(scheduler) -> bool:
    return type(scheduler).__name__ == "Client" and type(scheduler).__module__.startswith("distributed")


def stream(client, tasks, *, desc, progress_bar=None):
    """Yield the results of ``tasks`` (``dask.delayed`` objects of one graph) in their order, each released once
    yielded; a bar counts them.  In order, not as they finish: a .clw file written from them is the same byte for byte
    at every run (docs/chunked.md §5).  They are submitted together, so that what they share (a chunk read once,
    feeding its neighbours' halos) is computed once; results that finish before their turn wait for it, unbounded:
    Dask runs a transform's wavefront of halos some slabs ahead, and a slow early block (or one run again after its
    worker died) holds every later result (known-gaps.md).  A failed task is raised as soon as it fails."""
    with warnings.catch_warnings():  # a volume of thousands of blocks makes a graph of some MB: expected
        warnings.filterwarnings("ignore", message="Sending large graph")
        futures = client.compute(list(tasks))
    from distributed import as_completed

    places = {}  # a task's key -> its places in ``tasks`` (one graph may name a task twice)
    for i, future in enumerate(futures):
        places.setdefault(future.key, []).append(i)
    held, turn = {}, 0
    with progress(total=len(futures), desc=desc, enabled=progress_bar) as bar:
        # taken as they finish, so that a failed task (KilledWorker: every worker died) is raised at once; waiting
        # on the next in order instead could wait for ever on a task no worker is left to run
        for future, result in as_completed(futures, with_results=True):
            held.update((i, result) for i in places[future.key])
            future.release()
            while turn in held:
                bar.update(1)
                yield held.pop(turn)
                turn += 1
