"""The bench's ray-tracing cases (tools/bench.py; docs/benchmarks.md §4, §5, §7): ``raytrace`` (both paths, the
one-shot calls, VTK's composite beside), ``lod``, ``setup`` and ``refine``."""

from __future__ import annotations

import statistics
import time

import numpy as np

from bench_common import hydrogen_rgba, peak_resident_gib, summary, views  # first: it puts the checkout on sys.path

import clwave
from clwave.io.phantoms import phantom
from clwave.model.transfer import TransferFunction
from clwave.model.wavelet import WaveletVolume


def bench_raytrace(args) -> dict:
    rgba = hydrogen_rgba(args.size)
    wv = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05)
    out = dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", wavelet="cubic", levels=3, keep=0.05,
                            shading="phong, headlight", views=args.raytrace_views,
                            error_reference="B-spline path, float64 kernel at tolerance 1e-5, on the first view's "
                                            "64x64 centre crop (the timed crop where smaller)"),
               targets=dict(tolerance_1e_2_seconds=3.0, tolerance_1e_3_seconds=10.0), paths={})
    fast = None
    small = warm_up_model()
    for path, size, crop in (("bspline", args.raytrace_image, None),
                             ("wavelet", args.wavelet_image, args.wavelet_crop)):
        if path == "wavelet" and args.size > args.wavelet_max_size:
            continue
        clwave.RayTracer(small, device=args.device, field=path)  # warm-up: the set-up's kernels built apart
        start = time.perf_counter()
        tracer = clwave.RayTracer(wv, device=args.device, field=path)
        setup = time.perf_counter() - start
        fast = fast or tracer
        out["paths"][path] = _raytrace_cases(tracer, fast, wv, size, crop, args.raytrace_views)
        out["paths"][path]["setup_seconds"] = setup
        if path == "bspline":
            meta = tracer.render(clwave.Camera(*views(1)[0], size=size), tolerance=1e-2).meta
            out["paths"][path]["bricks"] = brick_figures(tracer, meta)
    out["one_shot"] = one_shot_raytrace(wv, args)
    out["peak_resident_gib"] = peak_resident_gib()  # this process: phantom, model, both paths' tracers, images
    out["vtk_composite"] = vtk_composite(args)
    return out


def warm_up_model() -> WaveletVolume:
    """Hydrogen 24^3 RGBA, cubic, 3 levels, 5 %: a tracer of it builds the set-up's kernels, apart from the timing."""
    return WaveletVolume.from_volume(hydrogen_rgba(24), wavelet="cubic", levels=3).threshold(keep=0.05)


def one_shot_raytrace(wv, args) -> dict:
    """Wall seconds of repeated ``clwave.raytrace(wv, camera)`` calls at tolerance 1e-2 (the model keeps its
    tracer: the field is set up by the first call only) against the same renders with an explicit tracer."""
    cams = [clwave.Camera(az, el, size=args.raytrace_image) for az, el in views(args.raytrace_views)]
    wv.release()
    start = time.perf_counter()
    clwave.raytrace(wv, cams[0], tolerance=1e-2, device=args.device)
    out = dict(first_call_seconds=time.perf_counter() - start)
    tracer = clwave.RayTracer(wv, device=args.device)
    for name, kw in (("one_shot", dict(device=args.device)), ("reused_tracer", dict(tracer=tracer))):
        walls = []
        for cam in cams:
            start = time.perf_counter()
            clwave.raytrace(wv, cam, tolerance=1e-2, **kw)
            walls.append(time.perf_counter() - start)
        out[name] = summary(walls)
    out["ratio"] = out["one_shot"]["median"] / out["reused_tracer"]["median"]
    return out


def brick_figures(tracer, meta) -> dict:
    """The B-spline field's bricks (docs/raytracing.md §3, §6) and what one render of them did."""
    f = tracer.bricks
    return dict(bricks=len(f.levels), bricks_per_level=np.bincount(f.levels).tolist(), pool_bytes=f.pool_bytes,
                pool=meta["pool"], passes=meta["passes"], segments=meta["segments"],
                segments_by_lattice=meta["segments_by_lattice"],
                device_bytes=(f.pool_bytes if f.resident else 0) + 2 * f.bounds.nbytes)


def vtk_composite(args) -> dict | None:
    """VTK's shaded composite (tools/compare_peers.py, ``Render()`` alone) of the same phantom at the same image
    size, when VTK is installed: the ratio to beat next."""
    import importlib.util

    if importlib.util.find_spec("vtk") is None:
        return None
    import compare_peers

    case = dict(phantom="hydrogen", n=args.size, image=args.raytrace_image, views=views(args.raytrace_views),
                device=args.device, tf="hydrogen")
    res = compare_peers.in_process("vtk", case, ("composite",))
    return dict(seconds=summary(res["seconds"]), prepare_seconds=res["prepare"],
                framing="compare_peers' camera: the volume's diagonal spans the image")


def _raytrace_cases(tracer, fast, wv, size, crop, n_views) -> dict:
    """Tolerances 1e-2 and 1e-3 at ``size``² (or its ``crop``² centre), error on the first view's 64² centre.

    ``fast``: the B-spline-path tracer that renders the float64 reference.
    """
    # 16 rows: two row bands, so that PoCL also compiles the kernel again for a launch at a non-zero offset,
    # which it does the first time it meets one (about 1 s), here rather than in the first timed view
    compile_seconds = tracer.render(clwave.Camera(10.0, 5.0, size=(16, 8)), tolerance=1e-2).meta["compile_seconds"]

    def camera(az, el, pixels):  # the pixels x pixels centre of the size x size view
        full = clwave.Camera(az, el, size=size).view(wv)
        return clwave.Camera(az, el, size=pixels, extent=full.pixel * pixels)

    pixels = crop or size
    edge = min(64, pixels)
    centre = slice((pixels - edge) // 2, (pixels + edge) // 2)
    az0, el0 = views(n_views)[0]
    reference = fast.render(camera(az0, el0, edge), tolerance=1e-5, precision="double").image
    cases = {}
    for tol in (1e-2, 1e-3):
        results = [tracer.render(camera(az, el, pixels), tolerance=tol) for az, el in views(n_views)]
        runs = [r.meta for r in results]
        seconds = summary([m["render_seconds"] for m in runs])
        name = f"tolerance {tol:g} at {size}x{size}" + (f", {crop}x{crop} centre crop" if crop else "")
        cases[name] = dict(
            seconds=seconds, segments=statistics.median(m["segments"] for m in runs),
            segments_per_second=statistics.median(m["segments_per_second"] for m in runs),
            integrand_evaluations=statistics.median(m["integrand_evaluations"] for m in runs),
            rays_active_list_overflowed=statistics.median(m["rays_active_list_overflowed"] for m in runs),
            max_error_vs_float64_crop=float(np.abs(results[0].image[centre, centre] - reference).max()))
        if crop:  # the centre is the densest part of the view: an upper estimate
            cases[name]["full_image_seconds_estimate"] = seconds["median"] * (size / crop) ** 2
    return dict(image=f"{size}x{size}", compile_seconds=compile_seconds, cases=cases)


def bench_lod(args) -> dict:
    """Level of detail and progressive ray tracing (docs/raytracing.md §8, §9): hydrogen RGBA, cubic, 3 levels,
    5 % and 0.1 % kept, shaded, tolerance 1e-2, ``--raytrace-image``; set-up without and with every detail
    (``lod=True``), each detail's render (interleaved over the views, detail by detail per view), the time to
    change detail (the first render at a detail: its bounds laid out; then kept), and the progressive frames of
    the first view: time since the start, detail, reduction, measured and estimated relative RMS error."""
    rgba = hydrogen_rgba(args.size)
    model = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3)
    small = warm_up_model()
    clwave.RayTracer(small, device=args.device, lod=True)  # warm-up: the set-up's kernels built apart
    cams = [clwave.Camera(az, el, size=args.raytrace_image) for az, el in views(args.raytrace_views)]
    out = dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", wavelet="cubic", levels=3,
                            tolerance=1e-2, image=args.raytrace_image, views=args.raytrace_views), keeps={})
    for keep in (0.05, 0.001):
        wv = model.threshold(keep=keep)
        case = {}
        for lod in (False, True):
            start = time.perf_counter()
            tracer = clwave.RayTracer(wv, device=args.device, lod=lod)
            case["setup_lod" if lod else "setup"] = dict(seconds=time.perf_counter() - start,
                                                         pool_bytes=tracer.bricks.pool_bytes)
        details = list(range(wv.levels + 1)) + [clwave.Detail(pixels=1.0)]
        tracer.render(cams[0], tolerance=1e-2, detail=None)  # the kernel built apart
        change, walls, metas = {}, {}, {}
        for cam in cams:
            for detail in details:
                res = tracer.render(cam, tolerance=1e-2, detail=detail)
                change.setdefault(repr(detail), res.meta["detail_seconds"])  # the first at this detail
                walls.setdefault(repr(detail), []).append(res.meta["render_seconds"])
                metas[repr(detail)] = res.meta
        case["details"] = {k: dict(render=summary(walls[k]), change_seconds=change[k], detail=metas[k]["detail"],
                                   segments=metas[k]["segments"], bricks=metas[k]["bricks"],
                                   segments_by_lattice=metas[k]["segments_by_lattice"]) for k in walls}
        frames = []
        for f in tracer.refine(cams[0], tolerance=1e-2):
            frames.append(f)
        case["progressive"] = [{k: f.figures()[k] for k in ("detail", "reduction", "seconds", "relative_rms_error",
                                                            "estimated_relative_rms_error", "relative_max_error",
                                                            "estimated_relative_max_error")} for f in frames]
        out["keeps"][str(keep)] = case
    out["peak_resident_gib"] = peak_resident_gib()
    return out


def bench_setup(args) -> dict:
    """The ray tracer's set-up (``RayTracer(...)``: plan, expansion, mixed pieces, bounds; docs/benchmarks.md §7):
    hydrogen RGBA, cubic, 3 levels, 5 % and 0.1 %, without and with every detail (``lod=True``), ``--repeats``
    set-ups after a warm-up that builds the kernels; the expansion's share (``BrickField.seconds``), the pool,
    slots and mixed bricks."""
    rgba = hydrogen_rgba(args.size)
    model = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3)
    small = warm_up_model()
    clwave.RayTracer(small, device=args.device, lod=True)
    out = dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", wavelet="cubic", levels=3,
                            repeats=args.repeats), cases={})
    for keep in (0.05, 0.001):
        wv = model.threshold(keep=keep)
        for lod in (False, True):
            walls, expansion = [], []
            for _ in range(args.repeats):
                start = time.perf_counter()
                tracer = clwave.RayTracer(wv, device=args.device, lod=lod)
                walls.append(time.perf_counter() - start)
                expansion.append(tracer.bricks.seconds)
            field = tracer.bricks
            out["cases"][f"{keep} lod={lod}"] = dict(
                setup=summary(walls), expansion=summary(expansion), pool_bytes=field.pool_bytes,
                slots=len(field.levels), mixed_bricks=int(np.sum(field.mixes[:, 0] >= 0)), pieces=len(field.pieces))
    out["peak_resident_gib"] = peak_resident_gib()
    return out


def bench_refine(args) -> dict:
    """``RayTracer.refine`` against one direct render of the same view (docs/raytracing.md §9), interleaved (render,
    refine, render, refine, ...) over ``--raytrace-views`` views: hydrogen at ``--size``^3, cubic, 3 levels, 5 %,
    shaded, tolerance 1e-2, ``--raytrace-image``; an RGBA model (the preset classified first) and the scalar one
    classified at render time.  Per view the render's seconds and segments, the sequence's (every render of it,
    pilot included: ``tracer.render`` counted), the first frame's seconds, and each frame's reduction, seconds since
    the start, measured and estimated relative errors."""
    tf = TransferFunction.preset("hydrogen")
    vol = phantom("hydrogen", n=args.size)
    models = dict(rgba=(WaveletVolume.from_volume(tf.classify(vol), wavelet="cubic", levels=3), {}),
                  scalar=(WaveletVolume.from_volume(vol, wavelet="cubic", levels=3), dict(transfer_function=tf)))
    cams = [clwave.Camera(az, el, size=args.raytrace_image) for az, el in views(args.raytrace_views)]
    out = dict(setting=dict(volume=f"hydrogen {args.size}^3 (preset)", wavelet="cubic", levels=3, keep=0.05,
                            tolerance=1e-2, image=args.raytrace_image, views=args.raytrace_views), models={})
    for name, (model, extra) in models.items():
        tracer = clwave.RayTracer(model.threshold(keep=0.05), device=args.device)
        render, made = tracer.render, []
        tracer.render = lambda *a, **k: made.append(render(*a, **k)) or made[-1]  # counts the sequence's renders
        tracer.render(clwave.Camera(10.0, 5.0, size=(16, 8)), tolerance=1e-2, **extra)  # the kernel built apart
        rounds = []
        for cam in cams:
            made.clear()
            start = time.perf_counter()
            direct = tracer.render(cam, tolerance=1e-2, **extra)
            one = dict(render_seconds=time.perf_counter() - start, render_segments=direct.meta["segments"])
            made.clear()
            start = time.perf_counter()
            frames = [(f, time.perf_counter() - start) for f in tracer.refine(cam, tolerance=1e-2, **extra)]
            one.update(refine_seconds=time.perf_counter() - start, first_frame_seconds=frames[0][1],
                       refine_segments=sum(r.meta["segments"] for r in made), renders=len(made),
                       frames=[dict(reduction=f.reduction, seconds=at, **{k: v for k, v in f.figures().items()
                                                                          if "error" in k}) for f, at in frames])
            one.update(refine_over_render=one["refine_seconds"] / one["render_seconds"],
                       segments_over_render=one["refine_segments"] / one["render_segments"])
            rounds.append(one)
        out["models"][name] = dict(refine_over_render=summary([r["refine_over_render"] for r in rounds]),
                                   segments_over_render=summary([r["segments_over_render"] for r in rounds]),
                                   first_frame_over_render=summary([r["first_frame_seconds"] / r["render_seconds"]
                                                                    for r in rounds]), rounds=rounds)
    out["peak_resident_gib"] = peak_resident_gib()
    return out
