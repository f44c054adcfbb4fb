"""Splatting's progressive error estimate against the measured error (docs/splatting.md §5, docs/benchmarks.md §15):
issue #30's bar, the estimate ``>=`` the measured relative RMS and max error on 95 % of the intermediate frames and
``<= 4x`` it on 95 %, over a sweep of volumes, views and thresholds, with the estimate's share of each view.

Every intermediate frame of ``--steps`` (8) steps at 5 % and 30 % kept; orthographic at (30, 20), (0, 0), (75, 60),
(130, -40) and ``ConeBeam`` s at dso 1.6, 3 and 8 times the volume's extent (those refused are left out)::

    tools/bench_estimate.py --size 32 --image 32 --wavelet quintic            # the ten volumes at 32^3, 32^2
    tools/bench_estimate.py --size 128 --image 512 --volumes shepp-logan --wavelet quintic

The estimate's time is taken inside the same views (``SplatEstimate.__init__`` and ``add``); its share is of the
view's frames (the final image, rendered as the last frame, included).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy.ndimage import gaussian_filter

from bench_common import machine  # first: it puts the checkout on sys.path

import clwave
from clwave.io.phantoms import phantom
from clwave.splat import estimate as estimate_module
from clwave.splat.renderer import SplatRenderer

ORTHOGRAPHIC = ((30, 20), (0, 0), (75, 60), (130, -40))
CONES = (1.6, 3.0, 8.0)  # dso in volume extents (dsd 1.5 times it)
KEEPS = (0.05, 0.3)


def volume(kind, n) -> clwave.Volume:
    """The sweep's ten kinds of volume at about n voxels a side (seeded)."""
    rng = np.random.default_rng(2026)
    if kind in ("hydrogen", "marschner-lobb", "shepp-logan"):
        return phantom(kind, n)
    if kind == "ct-like":  # Shepp-Logan as a CT's thick slices (3:1 spacing)
        return clwave.Volume(phantom("shepp-logan", n).data[::3].copy(), spacing=(3.0, 1.0, 1.0))
    if kind.startswith("smooth-"):  # smooth random of the given width in voxels
        return clwave.Volume(gaussian_filter(rng.standard_normal((n,) * 3), float(kind[7:])).astype(np.float32))
    if kind == "white-noise":
        return clwave.Volume(rng.random((n,) * 3).astype(np.float32))
    if kind == "blobs":  # eight Gaussian blobs of 1/16 to 1/6 of the side
        z, y, x = np.mgrid[:n, :n, :n].astype(np.float32)
        data = np.zeros((n,) * 3, np.float32)
        for centre, width, height in zip(rng.uniform(0.2, 0.8, (8, 3)) * n, rng.uniform(n / 16, n / 6, 8),
                                         rng.uniform(0.3, 1.0, 8)):
            data += height * np.exp(-((z - centre[0]) ** 2 + (y - centre[1]) ** 2 + (x - centre[2]) ** 2)
                                    / (2 * width ** 2))
        return clwave.Volume(data)
    if kind == "anisotropic":  # smooth random on voxels 4 times as wide along x
        return clwave.Volume(gaussian_filter(rng.standard_normal((n, n, max(2, n // 4))), 1.0).astype(np.float32),
                             spacing=(1.0, 1.0, 4.0))
    if kind == "sparse-points":  # n points of random height in an empty volume
        data = np.zeros((n,) * 3, np.float32)
        data[tuple(rng.integers(0, n, (3, n)))] = rng.uniform(0.5, 1.0, n)
        return clwave.Volume(data)
    raise SystemExit(f"unknown volume {kind!r}: name one of {', '.join(KINDS)}")


KINDS = ("hydrogen", "marschner-lobb", "shepp-logan", "ct-like", "smooth-1.5", "smooth-3", "white-noise", "blobs",
         "anisotropic", "sparse-points")


def cameras(vol, size, views) -> list:
    extent = float(np.max(np.array(vol.shape) * np.array(vol.spacing)))
    out = [(f"ortho {a},{e}", clwave.Camera(a, e, size)) for a, e in ORTHOGRAPHIC]
    out += [(f"cone {f}", clwave.ConeBeam(f * extent, 1.5 * f * extent, size, pixel=1.3 * 1.5 * extent / size,
                                          azimuth=40, elevation=25)) for f in CONES]
    return [(name, camera) for name, camera in out if views == "all" or name.split()[0] == views]


class Timer:
    """Seconds spent in SplatEstimate's set-up and frames (wrapped for the run)."""

    def __init__(self):
        self.seconds = 0.0
        cls = estimate_module.SplatEstimate
        self.restore = {name: getattr(cls, name) for name in ("__init__", "add")}
        for name, method in self.restore.items():
            setattr(cls, name, self._timed(method))

    def _timed(self, method):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
        return timed

    def close(self):
        for name, method in self.restore.items():
            setattr(estimate_module.SplatEstimate, name, method)


def run_case(vol, camera, wavelet, levels, keep, steps, timer, warm_up, save=None) -> dict:
    wv = clwave.WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels).threshold(keep=keep)
    r = SplatRenderer(wv)
    if warm_up:  # the process's first view: its kernels built
        list(clwave.progressive(wv, camera, steps=2, renderer=r))
    timer.seconds, start = 0.0, time.perf_counter()
    frames = list(clwave.progressive(wv, camera, steps=steps, renderer=r))
    seconds = time.perf_counter() - start
    rows = [frame.figures() for frame in frames[:-1]]
    if save:  # the frames, to try changes of the estimate on without rendering (the model is remade from the volume)
        np.savez_compressed(save, images=np.array([f.image for f in frames]),
                            counts=np.array([f.coefficients for f in frames]))
    return dict(rms=[f["estimated_relative_rms_error"] / f["relative_rms_error"] for f in rows],
                max=[f["estimated_relative_max_error"] / f["relative_max_error"] for f in rows],
                view_seconds=seconds, estimate_seconds=timer.seconds)


def rates(ratios) -> dict:
    ratios = np.asarray(ratios)
    return dict(frames=len(ratios), at_least=float(np.mean(ratios >= 1)), within_4x=float(np.mean(ratios <= 4)),
                median=float(np.median(ratios)) if len(ratios) else None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=32, help="voxels a side (default 32)")
    ap.add_argument("--image", type=int, default=32, help="pixels a side (default 32)")
    ap.add_argument("--volumes", default=",".join(KINDS), help="comma-separated kinds (default all ten)")
    ap.add_argument("--wavelet", default="cubic")
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument("--views", choices=("all", "ortho", "cone"), default="all")
    ap.add_argument("--json", help="write every case's ratios here")
    ap.add_argument("--frames", help="save every case's frames (images, coefficient counts) in this folder")
    args = ap.parse_args(argv)
    timer, cases = Timer(), []
    try:
        for kind in args.volumes.split(","):
            vol = volume(kind, args.size)
            for name, camera in cameras(vol, args.image, args.views):
                for keep in KEEPS:
                    try:
                        save = args.frames and f"{args.frames}/{kind}_{name.replace(' ', '_')}_{keep}.npz"
                        case = run_case(vol, camera, args.wavelet, args.levels, keep, args.steps, timer, not cases,
                                        save)
                    except clwave.ClwaveError as exc:  # a cone too near for the coarsest level: left out
                        print(f"{kind:14s} {name:14s} {keep:4.2f} refused: {str(exc)[:60]}", flush=True)
                        break
                    case.update(volume=kind, view=name, keep=keep)
                    cases.append(case)
                    print(f"{kind:14s} {name:14s} {keep:4.2f} rms >= {np.mean(np.array(case['rms']) >= 1):4.2f} "
                          f"max >= {np.mean(np.array(case['max']) >= 1):4.2f} min max ratio "
                          f"{min(case['max']):5.2f} share {case['estimate_seconds'] / case['view_seconds']:.3f}",
                          flush=True)
    finally:
        timer.close()
    summary = dict(setting=vars(args), machine=machine(),
                   rms=rates([x for c in cases for x in c["rms"]]), max=rates([x for c in cases for x in c["max"]]),
                   share=dict(median=float(np.median([c["estimate_seconds"] / c["view_seconds"] for c in cases]))),
                   volumes={kind: dict(rms=rates([x for c in cases if c["volume"] == kind for x in c["rms"]]),
                                       max=rates([x for c in cases if c["volume"] == kind for x in c["max"]]))
                            for kind in args.volumes.split(",")})
    print(json.dumps({k: summary[k] for k in ("rms", "max", "share", "volumes")}, indent=1))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(summary, cases=cases), fh)


if __name__ == "__main__":
    main()
