"""The bench's post-classification cases (tools/bench.py; docs/raytracing.md §10, docs/benchmarks.md §8): ``post``,
``pools`` and ``pools-lod``."""

from __future__ import annotations

import statistics
import time

import numpy as np

from bench_common import peak_resident_gib, summary, views  # first: it puts the checkout on sys.path

import clwave
from clwave.io.phantoms import phantom
from clwave.model.transfer import TransferFunction
from clwave.model.wavelet import WaveletVolume


def bench_post(args) -> dict:
    """Post-classification (docs/raytracing.md §10) against pre-classification of the same phantom: hydrogen
    (preset), cubic, 3 levels, 5 %, shaded, at ``--raytrace-image`` for tolerances 1e-2 and 1e-3, renders
    interleaved (post, pre, post, pre, ...) over ``--raytrace-views`` views; a change of transfer function or
    window (the table and the classified bounds: meta ``classify_seconds``); the brick pools; the error against a
    float64 render (tolerance 1e-5) of the same post-classified model on the first view's 64x64 centre, for
    hydrogen and for Marschner-Lobb (``grey``) and a CT-like phantom (``ct-bone``) at 64^3, and the MNI152 MRI
    (``mri``) when nilearn is installed; VTK's composite against the post-classified render, interleaved."""
    tf = TransferFunction.preset("hydrogen")
    vol = phantom("hydrogen", n=args.size)
    models = dict(post=WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=0.05),
                  pre=WaveletVolume.from_volume(tf.classify(vol), wavelet="cubic", levels=3).threshold(keep=0.05))
    tracers, setup, compile_seconds = {}, {}, {}
    for name, wv in models.items():
        start = time.perf_counter()
        tracers[name] = clwave.RayTracer(wv, device=args.device)
        setup[name] = time.perf_counter() - start
        extra = dict(transfer_function=tf) if name == "post" else {}
        compile_seconds[name] = tracers[name].render(clwave.Camera(10.0, 5.0, size=(16, 8)), tolerance=1e-2,
                                                     **extra).meta["compile_seconds"]
    cams = [clwave.Camera(az, el, size=args.raytrace_image) for az, el in views(args.raytrace_views)]
    cases = {}
    for tol in (1e-2, 1e-3):
        seconds = dict(post=[], pre=[])
        segments = dict(post=[], pre=[])
        for cam in cams:  # interleaved: the machine's load falls on both alike
            for name in ("post", "pre"):
                extra = dict(transfer_function=tf) if name == "post" else {}
                meta = tracers[name].render(cam, tolerance=tol, **extra).meta
                seconds[name].append(meta["render_seconds"])
                segments[name].append(meta["segments"])
        cases[f"tolerance {tol:g}"] = dict(
            seconds={k: summary(v) for k, v in seconds.items()},
            segments={k: statistics.median(v) for k, v in segments.items()},
            post_over_pre=[a / b for a, b in zip(seconds["post"], seconds["pre"])])
    changes = []
    small = clwave.Camera(*views(1)[0], size=64)
    for window in ((0.02, 1.0), (0.05, 0.95), (0.1, 0.8), (0.0, 0.6), (0.2, 1.0)):  # each a change
        for preset in ("hydrogen", "grey"):
            changes.append(tracers["post"].render(small, tolerance=1e-2, transfer_function=TransferFunction.preset(
                preset, window=window)).meta["classify_seconds"])
    pools = {name: t.bricks.pool_bytes for name, t in tracers.items()}
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", wavelet="cubic", levels=3, keep=0.05,
                             shading="phong, headlight", image=f"{args.raytrace_image}^2", views=len(cams),
                             transfer_function="hydrogen preset"),
                setup_seconds=setup, compile_seconds=compile_seconds, cases=cases,
                tf_change_seconds=summary(changes), pool_bytes=pools, pool_ratio=pools["post"] / pools["pre"],
                errors=post_errors(tracers["post"], models["post"], tf, args),
                vtk_composite=post_vs_vtk(tracers["post"], tf, args),
                peak_resident_gib=peak_resident_gib(), targets=dict(tf_change_seconds=0.05, pool_ratio=0.3,
                                                                     post_over_pre=1.0, post_over_vtk=1.5))


def post_vs_vtk(tracer, tf, args) -> dict | None:
    """VTK's composite ray caster of the scalar volume under the same preset (tools/compare_peers.py: post-classified
    too), against the post-classified render of the same views at tolerance 1e-2, interleaved (VTK, clwave, VTK,
    clwave; VTK in its own process, its ``Render()`` alone, its first view, the set-up, left out), when VTK is
    installed."""
    import importlib.util

    if importlib.util.find_spec("vtk") is None:
        return None
    import compare_peers

    case = dict(phantom="hydrogen", n=args.size, image=args.raytrace_image, views=views(max(3, args.raytrace_views)),
                device=args.device, tf=tf.name)
    seconds = dict(vtk=[], post=[])
    for _ in range(2):
        seconds["vtk"] += compare_peers.in_process("vtk", case, ("composite",))["seconds"][1:]
        seconds["post"] += [tracer.render(compare_peers.camera(case, az, el), tolerance=1e-2, transfer_function=tf)
                            .meta["render_seconds"] for az, el in case["views"][1:]]
    return dict(seconds={k: summary(v) for k, v in seconds.items()},
                post_over_vtk=statistics.median(seconds["post"]) / statistics.median(seconds["vtk"]),
                framing="compare_peers' camera: the volume's diagonal spans the image")


def ct_like(n) -> clwave.Volume:
    """Shepp-Logan in Hounsfield units: outside -1000, the brain's ellipses about 0..60, the skull 1200."""
    v = phantom("shepp-logan", n=n).data
    return clwave.Volume(np.interp(v, [0.0, 0.1, 0.5, 1.0], [-1000.0, 0.0, 60.0, 1200.0]).astype(np.float32))


def bench_pools(args) -> dict:
    """The scalar tracer's packed brick pool over the RGBA tracer's for the same volume classified by its preset (cubic,
    3 levels, 5 %), and the time ``pack`` took (docs/raytracing.md §10; the issue's target 0.30)."""
    from clwave.raytrace import classified

    seconds, pack = [], classified.pack

    def timed(*pack_args):
        start = time.perf_counter()
        out = pack(*pack_args)
        seconds.append(time.perf_counter() - start)
        return out

    out = {}
    cases = [(f"hydrogen {args.size}^3", phantom("hydrogen", n=args.size), "hydrogen"),
             ("hydrogen 128^3", phantom("hydrogen", n=128), "hydrogen"),
             ("marschner-lobb 128^3", phantom("marschner-lobb", n=128), "grey"),
             ("ct-like 128^3 (Shepp-Logan in HU)", ct_like(128), "ct-bone")]
    classified.pack = timed
    try:
        for name, vol, preset in cases:
            tf = TransferFunction.preset(preset)
            models = [WaveletVolume.from_volume(v, wavelet="cubic", levels=3).threshold(keep=0.05)
                      for v in (vol, tf.classify(vol))]
            post = clwave.RayTracer(models[0], device=args.device)
            post.render(clwave.Camera(10.0, 5.0, size=(8, 8)), tolerance=1e-2, transfer_function=tf)  # packs
            pre = clwave.RayTracer(models[1], device=args.device).bricks.pool_bytes
            out[name] = dict(transfer_function=preset, post_bytes=post.bricks.pool_bytes, pre_bytes=pre,
                             ratio=post.bricks.pool_bytes / pre, pack_seconds=seconds[-1])
    finally:
        classified.pack = pack
    return dict(setting=dict(wavelet="cubic", levels=3, keep=0.05), pools=out, target_ratio=0.3,
                peak_resident_gib=peak_resident_gib())


def bench_pools_lod(args) -> dict:
    """The packed scalar pool of a tracer of every detail (``lod=True``) over the RGBA one's, hydrogen at ``--size``³
    (cubic, 3 levels, 5 %): with a step for the full-detail slots and one for the coarser details' (its full-detail
    slots packed as without level of detail, docs/raytracing.md §10), and as one step for the whole pool would pack
    it (the packing before), with the steps."""
    from clwave.raytrace import classified

    seen, pack = {}, classified.pack

    def spy(scalar, boxes, full=None):
        seen.update(scalar=scalar.copy(), boxes=boxes, full=full)
        return pack(scalar, boxes, full)

    tf = TransferFunction.preset("hydrogen")
    vol = phantom("hydrogen", n=args.size)
    models = [WaveletVolume.from_volume(v, wavelet="cubic", levels=3).threshold(keep=0.05)
              for v in (vol, tf.classify(vol))]
    classified.pack = spy
    try:
        post = clwave.RayTracer(models[0], device=args.device, lod=True)
        post.render(clwave.Camera(10.0, 5.0, size=(8, 8)), tolerance=1e-2, transfer_function=tf)  # packs
    finally:
        classified.pack = pack
    steps = post.quant.get()["step"]
    one_step = 4 * len(pack(seen["scalar"], seen["boxes"])[0])
    del seen["scalar"]
    pre = clwave.RayTracer(models[1], device=args.device, lod=True).bricks.pool_bytes
    direct = clwave.RayTracer(models[0], device=args.device)
    direct.render(clwave.Camera(10.0, 5.0, size=(8, 8)), tolerance=1e-2, transfer_function=tf)
    full = seen["full"]
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", wavelet="cubic", levels=3, keep=0.05, lod=True),
                post_bytes=post.bricks.pool_bytes, pre_bytes=pre, ratio=post.bricks.pool_bytes / pre,
                one_step_bytes=one_step, one_step_ratio=one_step / pre, full_detail_step=float(steps[full][0]),
                coarse_step=float(steps[~full].max()), slots=len(steps), full_detail_slots=int(full.sum()),
                direct_post_bytes=direct.bricks.pool_bytes, direct_step=float(direct.quant.get()["step"][0]),
                target_ratio=0.3, peak_resident_gib=peak_resident_gib())


def post_errors(tracer, wv, tf, args) -> dict:
    """Max error of post-classified float32 renders at 1e-2 and 1e-3 against a float64 render at 1e-5 of the same
    model, on a 64x64 centre of the first view (``--raytrace-image`` framing)."""
    out = {}
    cases = [("hydrogen", wv, tf, tracer)]
    volumes = [("marschner-lobb 64^3", phantom("marschner-lobb", n=64), "grey"),
               ("ct-like 64^3 (Shepp-Logan in HU)", ct_like(64), "ct-bone")]
    import importlib.util

    if importlib.util.find_spec("nilearn") is not None:  # the MNI152 T1 template inside the nilearn wheel
        from figures import default_scan

        volumes.append(("MNI152 T1 MRI 197x233x189", clwave.load(default_scan()), "mri"))
    for name, vol, preset in volumes:
        model = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=0.05)
        cases.append((name, model, TransferFunction.preset(preset), clwave.RayTracer(model, device=args.device)))
    for name, model, function, t in cases:
        full = clwave.Camera(*views(1)[0], size=args.raytrace_image).view(model)
        cam = clwave.Camera(*views(1)[0], size=64, extent=full.pixel * 64)
        reference = t.render(cam, tolerance=1e-5, precision="double", transfer_function=function).image
        out[name] = {f"tolerance {tol:g}": float(np.abs(t.render(cam, tolerance=tol, transfer_function=function)
                                                         .image - reference).max()) for tol in (1e-2, 1e-3)}
        out[name]["transfer_function"] = function.name
    return out
