"""The bench's shared helpers (tools/bench.py and its families, tools/bench_*.py): the machine and the device
described, the statistics of a sample, the views, the peak resident memory, the classified phantom."""

from __future__ import annotations

import os
import platform
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402
from clwave.io.phantoms import phantom  # noqa: E402
from clwave.model.transfer import TransferFunction  # noqa: E402


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return dict(cpu=cpu, cores=os.cpu_count(), python=platform.python_version(),
                numpy=np.__version__, clwave=clwave.__version__, system=platform.platform())


def device(request) -> dict:
    try:
        return clwave.ComputeContext.get(request).describe()
    except clwave.ClwaveError as exc:
        return dict(error=str(exc))


def summary(samples) -> dict:
    return dict(median=statistics.median(samples), min=min(samples), max=max(samples), runs=len(samples))


def views(count):
    """Distinct views: a golden-angle spiral of azimuths and elevations."""
    return [(137.508 * i % 360.0, -60.0 + 120.0 * (i + 0.5) / count) for i in range(count)]


def peak_resident_gib() -> float:
    """This process's peak resident memory so far (on PoCL the device's buffers are in it too)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def hydrogen_rgba(n) -> clwave.Volume:
    """The hydrogen phantom of ``n``^3 voxels classified by its preset (RGBA)."""
    return TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=n))
