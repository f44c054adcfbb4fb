"""Progressive ray tracing's error estimates on random volumes (issue #30, docs/raytracing.md §9,
docs/benchmarks.md §16): a set made by seed, not tuned on, of random smooth and sharp volumes of odd shapes and
anisotropic spacings, pre-classified RGBA or scalar classified at render time with a preset, 1–4 levels of a random
order, 0.1–20 % kept, each seen once shaded, unshaded or in X-ray mode; per case both the direct frames
(``clwave.progressive(..., method="raytrace")``) and the staged coarse frames (``RayTracer.open(...).refine``, the
full stage held back until they are made, as tools/staged_estimate.py), every frame before the last measured
against the final image (a case whose final image sees nothing is left out: an error relative to its largest value
has no meaning).  Even seeds are the tuning half, odd seeds the held-out half.

    PYTHONPATH=$PWD .venv/bin/python tools/estimate_sweep.py --seeds 0-39 [--json out.json]

Prints a line per frame and, per half and per kind (direct, staged at 1 level, at 2–4 levels), the share of frames
whose RMS and max estimates are within [1, 4] of their error, and the worst ratios."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tools")]  # run from a checkout

import clwave  # noqa: E402
from staged_estimate import coarse_frames  # noqa: E402

PRESETS = ("grey", "hydrogen", "mri", "ct-bone")


def case(seed) -> dict:
    """The random case of ``seed``: a volume, how it is modelled and seen."""
    rng = np.random.default_rng(seed)
    levels = int(rng.integers(1, 5))
    least = 2 ** (levels + 1)  # levels <= floor(log2(min axis)) - 1
    shape = [int(rng.integers(max(least, 6), 72)) for _ in range(3)]
    if rng.random() < 0.3:  # a long, thin axis
        shape[int(rng.integers(3))] = int(rng.integers(100, 200))
    while np.prod(shape) > 160_000:
        axis = int(np.argmax(shape))
        shape[axis] = max(least, shape[axis] * 3 // 4)
    field = gaussian_filter(rng.random(shape), rng.uniform(1.0, 4.0), mode="wrap")
    field = (field - field.min()) / np.ptp(field)
    sharp = rng.random() < 0.5
    if sharp:  # steps between a few flat values
        field = np.digitize(field, np.sort(rng.uniform(0.3, 0.8, int(rng.integers(1, 4))))) / 3.0
    if rng.random() < 0.5:  # an empty background: the content clamp's case
        field = np.where(field > np.quantile(field, rng.uniform(0.4, 0.9)), field, 0.0)
    preset = str(rng.choice(PRESETS))
    data = np.interp(field, [0, 0.5, 1], [-1000, 100, 1800]) if preset == "ct-bone" else field
    spacing = tuple(float(s) for s in np.round(rng.uniform(0.5, 2.5, 3), 2))
    mode = str(rng.choice(["shaded", "unshaded", "xray"]))
    size = int(rng.integers(64, 200))
    camera = dict(azimuth=float(rng.uniform(-180, 180)), elevation=float(rng.uniform(-60, 60)),
                  size=(size, int(rng.integers(64, 200))) if rng.random() < 0.5 else size)
    if rng.random() < 0.25:
        camera.update(perspective=True, fov=float(rng.uniform(20, 50)))
    return dict(seed=seed, shape=tuple(shape), spacing=spacing, sharp=sharp, preset=preset, levels=levels,
                wavelet=str(rng.choice(["linear", "quadratic", "cubic", "cubic"])),
                keep=float(np.exp(rng.uniform(np.log(0.001), np.log(0.2)))),
                classify=str(rng.choice(["rgba", "post"])), mode=mode, camera=camera,
                data=data.astype(np.float32))


def run(c, tmp, direct=True) -> list:
    """Rows (kind, reduction, RMS and max errors and estimates) of case ``c``'s direct (where ``direct``) and staged
    frames."""
    volume = clwave.Volume(c["data"], spacing=c["spacing"][::-1])
    tf = clwave.TransferFunction.preset(c["preset"], window="auto" if c["preset"] != "ct-bone" else None)
    post = c["classify"] == "post"
    wv = clwave.WaveletVolume.from_volume(volume if post else tf.classify(volume), wavelet=c["wavelet"],
                                          levels=c["levels"]).threshold(keep=c["keep"])
    path = Path(tmp) / f"case{c['seed']}.clw"
    wv.save(path, overwrite=True)
    camera = clwave.Camera(**c["camera"])
    options = dict(absorption=c["mode"] != "xray", shading=c["mode"] == "shaded",
                   transfer_function=tf if post and c["mode"] != "xray" else None)
    frames = list(clwave.progressive(wv, camera, method="raytrace", tolerance=1e-2, **options)) if direct else []
    direct = [dict(f.figures(), reduction=f.reduction, kind="direct") for f in frames][:-1]
    staged = [dict(f, kind=f"staged {c['levels']}") for f in coarse_frames(path, camera, **options)]
    label = {k: c[k] for k in ("seed", "levels", "wavelet", "keep", "classify", "preset", "mode", "sharp", "shape")}
    out = []
    peaks = [f["final_peak"] for f in staged] + [float(np.max(np.abs(f.image))) for f in frames[-1:]]
    if not any(peaks):  # the final image sees nothing: an error relative to its largest value has no meaning
        print(f"{c['seed']:3d} the final image sees nothing: left out", flush=True)
        return out
    for f in direct + staged:
        row = dict(label, kind=f["kind"], reduction=f["reduction"])
        for n in ("rms", "max"):
            est, err = f[f"estimated_relative_{n}_error"], f[f"relative_{n}_error"]
            row.update({f"{n}_error": float(err), f"{n}_estimate": float(est),
                        f"{n}_ratio": float(est / err) if err > 0 else float("inf")})
        out.append(row)
        print(f"{c['seed']:3d} {row['kind']:9s} L{c['levels']} {c['wavelet']:9s} {c['keep']:6.2%} {c['classify']:4s} "
              f"{c['preset']:8s} {c['mode']:8s} {'sharp' if c['sharp'] else 'smooth'} /{row['reduction']:<2d} "
              f"rms {row['rms_error']:.2e} ({row['rms_ratio']:5.2f}x) max {row['max_error']:.2e} "
              f"({row['max_ratio']:5.2f}x)", flush=True)
    return out


def summary(rows) -> dict:
    """Per half and kind: frames, both within [1, 4], RMS and max ratio ranges."""
    figures = {}
    for half, parity in (("tuning", 0), ("held-out", 1)):
        for kind in ("direct", "staged 1", "staged 2-4"):
            sel = [r for r in rows if r["seed"] % 2 == parity and (r["kind"] == kind or (
                kind == "staged 2-4" and r["kind"].startswith("staged") and r["kind"] != "staged 1"))]
            if not sel:
                continue
            both = sum(all(1 <= r[f"{n}_ratio"] <= 4 for n in ("rms", "max")) for r in sel)
            fig = dict(frames=len(sel), both_within_1_4=both)
            for n in ("rms", "max"):
                ratios = [r[f"{n}_ratio"] for r in sel]
                fig[n] = dict(below_1=sum(x < 1 for x in ratios), above_4=sum(x > 4 for x in ratios),
                              lowest=min(ratios), highest=max(ratios))
            figures[f"{half} {kind}"] = fig
            print(f"{half:8s} {kind:10s} both in [1, 4] on {both}/{len(sel)}; " + "; ".join(
                f"{n} {fig[n]['lowest']:.2f}-{fig[n]['highest']:.2f}x, {fig[n]['below_1']} below 1, "
                f"{fig[n]['above_4']} above 4" for n in ("rms", "max")))
    return figures


def seeds(text) -> list:
    """Seeds from ``0-39`` or ``1,3,10-12``."""
    out = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += range(int(lo), int(hi or lo) + 1)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=seeds, default=seeds("0-39"), help="seeds, e.g. 0-39 or 1,3,10-12")
    parser.add_argument("--staged", action="store_true", help="the staged frames alone (the direct ones do not use "
                        "the coarse stage's estimate)")
    parser.add_argument("--json", help="write the rows and the summary here")
    args = parser.parse_args()
    rows = []
    warnings.simplefilter("ignore")  # the cases' own (fog, an empty view, a keep below the approximation)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            rows += run(case(seed), tmp, direct=not args.staged)
    figures = summary(rows)
    if args.json:
        Path(args.json).write_text(json.dumps(dict(rows=rows, summary=figures), indent=1, default=str))


if __name__ == "__main__":
    main()
