"""The staged tracer's coarse frames: their error estimate against their measured error (docs/raytracing.md §9,
docs/benchmarks.md §16).  The protocol of the docs' 96-frame table: the test volumes at 48³ (hydrogen,
Marschner–Lobb, a random smooth volume, the MNI152 MRI; ``model`` of tests/test_progressive_raytrace.py) saved as
``.clw``, 5 % and 0.5 % kept, two views at 128² and one at 256², shaded and X-ray, tolerance 1e-2, both coarse
frames of each refinement (the full stage held back until they are made), each measured against the whole file's
direct render.  ``--file PATH --size 512`` measures one file instead (hydrogen 256³ → 512²: one view, shaded).
``--held-out`` measures the volumes held out from the estimate's choices instead (:func:`held_out`: 80 frames),
``--fresh`` a set made before the eighteenth session's changes and never tuned on (:func:`fresh`: 48 frames).

    PYTHONPATH=$PWD .venv/bin/python tools/staged_estimate.py [--json out.json]

Prints a line per frame, with the file's two terms (the details' ``rho``, ``StagedTracer.missing``, and the clamp's
``kappa``, ``StagedTracer.outside``; also in the JSON rows), and the share of frames whose RMS and max estimates are
at least their error and at most 4x it."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # run from a checkout: the tests' models

import clwave  # noqa: E402
from clwave.raytrace.staged import StagedTracer  # noqa: E402
from test_progressive_raytrace import mni152, model  # noqa: E402

MODELS = ("hydrogen", "marschner-lobb", "random", "mri")
KEEPS = (0.05, 0.005)
VIEWS = (dict(azimuth=30, elevation=20, size=128), dict(azimuth=-60, elevation=35, size=128),
         dict(azimuth=120, elevation=-25, size=256))


def held_out(tmp) -> list:
    """The cases held out from the estimate's choices (docs/benchmarks.md §16), 5 % and 0.5 % kept, views (30°, 20°)
    and (−60°, 35°): Shepp–Logan 64³ (``grey``) and hydrogen 128³ at 256² (thirteenth session), Marschner–Lobb 96³
    (``hydrogen``) and the MNI152 MRI averaged over 2³ voxels (``mri``) at 256², and a random smooth volume 64³
    (``grey``) at 192² (fourteenth session)."""
    from scipy.ndimage import gaussian_filter

    noise = gaussian_filter(np.random.default_rng(7).random((64, 64, 64)), 2.7)
    volumes = (("shepp-logan 64", clwave.phantom("shepp-logan", 64), "grey", 256),
               ("hydrogen 128", clwave.phantom("hydrogen", 128), "hydrogen", 256),
               ("marschner-lobb 96", clwave.phantom("marschner-lobb", n=96), "hydrogen", 256),
               ("random 64", clwave.Volume(((noise - noise.min()) / np.ptp(noise)).astype(np.float32)), "grey", 192),
               ("mri 2³", mni152(step=2), None, 256))
    return saved(tmp, volumes, ((30, 20), (-60, 35)))


def fresh(tmp) -> list:
    """A held-out set made before the eighteenth session changed the estimate, and never tuned on: 5 % and 0.5 %
    kept, views (75°, 10°) and (−150°, −40°), none of them the protocol's or :func:`held_out`'s: a CT-like
    Shepp–Logan 64³ in HU (background −1000, the brain's 0.2 at +40, the skull's 1 at +1500) with ``ct-bone`` at
    256², a random smooth volume 80³ of a new seed (``grey``) at 192², hydrogen 96³ at 192²."""
    from scipy.ndimage import gaussian_filter

    head = clwave.phantom("shepp-logan", 64).data
    hu = np.interp(head, [0.0, 0.2, 1.0], [-1000.0, 40.0, 1500.0]).astype(np.float32)
    noise = gaussian_filter(np.random.default_rng(2026).random((80, 80, 80)), 2.3)
    volumes = (("ct shepp-logan 64", clwave.Volume(hu), "ct-bone", 256),
               ("random 80", clwave.Volume(((noise - noise.min()) / np.ptp(noise)).astype(np.float32)), "grey", 192),
               ("hydrogen 96", clwave.phantom("hydrogen", 96), "hydrogen", 192))
    return saved(tmp, volumes, ((75, 10), (-150, -40)))


def saved(tmp, volumes, angles) -> list:
    """Cases (label, path, camera keywords) of ``volumes`` (name, volume, preset or None for RGBA, image side):
    each classified, 3 cubic levels, saved at 5 % and 0.5 % kept under ``tmp``, seen from ``angles``."""
    cases = []
    for name, volume, preset, size in volumes:
        rgba = volume if preset is None else clwave.TransferFunction.preset(preset).classify(volume)
        full = clwave.WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3)
        for keep in KEEPS:
            path = Path(tmp) / f"{name.replace(' ', '_')}_{keep}.clw"
            full.threshold(keep=keep).save(path)
            cases.append((f"{name} {keep:.1%}", path, [dict(azimuth=a, elevation=e, size=size) for a, e in angles]))
    return cases


def coarse_frames(path, camera, tolerance=1e-2, **options) -> list:
    """The figures of both coarse frames of ``camera`` (the full stage reported not ready until they are made) and
    the final image's largest magnitude (``final_peak``); ``options`` as ``refine``'s."""
    ready = StagedTracer.ready
    StagedTracer.ready = property(lambda self: False)
    try:
        tracer = clwave.RayTracer.open(path)
        return [dict(f.figures(), reduction=f.reduction, missing=tracer.missing, outside=tracer.outside,
                     final_peak=float(np.max(np.abs(f.final_image()))))
                for f in tracer.refine(camera, tolerance=tolerance, **options) if f.meta["stage"] == "coarse"]
    finally:
        StagedTracer.ready = ready


def rows(cases) -> list:
    """Per case (label, path, camera keywords), both modes' coarse frames: label, mode, size, reduction, the
    measured and estimated relative errors and their ratios."""
    out = []
    for label, path, views in cases:
        for view in views:
            for absorption in (True, False):
                for f in coarse_frames(path, clwave.Camera(**view), absorption=absorption):
                    row = dict(case=label, mode="shaded" if absorption else "xray", view=view,
                               reduction=f["reduction"], missing=f["missing"], outside=f["outside"])
                    for n in ("rms", "max"):
                        est, err = f[f"estimated_relative_{n}_error"], f[f"relative_{n}_error"]
                        row.update({f"{n}_error": err, f"{n}_estimate": est, f"{n}_ratio": est / err})
                    out.append(row)
                    print(f"{label:24s} {row['mode']:6s} {view['size']:4d}² /{row['reduction']:<2d} "
                          f"rms {row['rms_error']:.2e} est {row['rms_estimate']:.2e} ({row['rms_ratio']:5.2f}x)  "
                          f"max {row['max_error']:.2e} est {row['max_estimate']:.2e} ({row['max_ratio']:5.2f}x)  "
                          f"rho {row['missing']:.3f} kappa {row['outside']:.3f}",
                          flush=True)
    return out


def summary(out) -> dict:
    def share(n, lo, hi):
        return sum(lo <= r[f"{n}_ratio"] <= hi for r in out)
    figures = {}
    for n in ("rms", "max"):
        ratios = [r[f"{n}_ratio"] for r in out]
        figures[n] = dict(frames=len(out), at_least=share(n, 1, float("inf")), within_1_4=share(n, 1, 4),
                          lowest=min(ratios), highest=max(ratios))
        print(f"{n}: estimate >= error on {figures[n]['at_least']}/{len(out)}, within [1, 4] on "
              f"{figures[n]['within_1_4']}/{len(out)}, ratios {min(ratios):.2f}-{max(ratios):.2f}")
    return figures


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--file", help="one .clw file instead of the 48³ test models")
    parser.add_argument("--size", type=int, default=512, help="its image side (with --file)")
    parser.add_argument("--held-out", action="store_true", help="the held-out volumes instead (held_out)")
    parser.add_argument("--fresh", action="store_true", help="the fresh held-out set instead (fresh)")
    parser.add_argument("--models", nargs="+", default=MODELS, choices=MODELS)
    parser.add_argument("--json", help="write the rows and the summary here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.file:
            cases = [(Path(args.file).name, args.file, [dict(azimuth=30, elevation=20, size=args.size)])]
        elif args.held_out:
            cases = held_out(tmp)
        elif args.fresh:
            cases = fresh(tmp)
        else:
            cases = []
            for name in args.models:
                for keep in KEEPS:
                    path = Path(tmp) / f"{name}_{keep}.clw"
                    model(name, keep=keep).save(path)
                    cases.append((f"{name} {keep:.1%}", path, VIEWS))
        out = rows(cases)
    figures = summary(out)
    if args.json:
        Path(args.json).write_text(json.dumps(dict(rows=out, summary=figures), indent=1))


if __name__ == "__main__":
    main()
