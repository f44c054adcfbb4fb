"""The bench's ``evaluate`` case (tools/bench.py): :meth:`WaveletVolume.evaluate` at many points (docs/benchmarks.md
§17)."""

from __future__ import annotations

import time
import tracemalloc

import numpy as np
from bench_common import summary  # first: it puts the checkout on sys.path

from clwave.io.phantoms import phantom
from clwave.model.wavelet import WaveletVolume


def bench_evaluate(args) -> dict:
    """Hydrogen scalar ``--size``³, cubic, 3 levels, 5 %: ``evaluate`` at ``--points`` counts of random points in the
    grid, the first call (nothing kept) and the next (the fine coefficients kept), ``--repeats`` each; the first
    call's peak of memory allocated (tracemalloc: NumPy's arrays, not the model); the band sum alone up to
    ``--bands-max-points``."""
    wv = WaveletVolume.from_volume(phantom("hydrogen", n=args.size), "cubic", levels=3).threshold(keep=0.05)
    half = np.array(wv.shape[::-1]) * np.array(wv.spacing[::-1]) / 2
    wv.evaluate(np.array(wv.origin)[None], "fine")  # warm-up, untimed (docs/benchmarks.md §1)
    out = {}
    for count in args.points:
        pts = np.array(wv.origin) + np.random.default_rng(count).uniform(-1, 1, (count, 3)) * half
        first, next_ = [], []
        for _ in range(args.repeats):
            wv.release()
            start = time.perf_counter()
            wv.evaluate(pts)
            first.append(time.perf_counter() - start)
            start = time.perf_counter()
            wv.evaluate(pts)
            next_.append(time.perf_counter() - start)
        wv.release()
        tracemalloc.start()
        wv.evaluate(pts)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        case = dict(first_seconds=summary(first), next_seconds=summary(next_), first_peak_mib=peak / 2 ** 20,
                    kept_mib=sum(c.nbytes for c, _ in wv._fine.values()) / 2 ** 20)
        if count <= args.bands_max_points:
            start = time.perf_counter()
            wv.evaluate(pts, "bands")
            case["bands_seconds"] = time.perf_counter() - start
        out[str(count)] = case
    return out
