"""The bench's cases from files, each step in a process of its own (``bench.py --scale-step SPEC``, its peak
memory its own; docs/benchmarks.md §6, §13): ``scale`` (a Zarr store compressed chunk by chunk, its file splatted and
ray traced) and ``first-image``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench_common import hydrogen_rgba, peak_resident_gib, summary, views  # first: it puts the checkout on sys.path
from bench_raytrace import brick_figures

import clwave
from clwave.model.transfer import TransferFunction
from clwave.model.wavelet import WaveletVolume


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
    proc = subprocess.run([sys.executable, str(Path(__file__).with_name("bench.py")), "--scale-step", json.dumps(spec)],
                          check=True, capture_output=True, text=True)
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
    path = first_image_file(args)
    if args.first_image_file is None and not path.exists():
        args.scratch.mkdir(parents=True, exist_ok=True)
        rgba = hydrogen_rgba(args.size)
        WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05).save(path)
    spec = dict(model=str(path), device=args.device, image=args.raytrace_image)
    for step in ("first-shaded", "first-xray"):  # warm-up: both kernels built, the file cached
        _scale_step(dict(spec, step=step, frames=1))
    return dict(setting=dict(file=str(path), image=args.raytrace_image, tolerance=1e-2, device_memory="2GiB"),
                xray=_scale_step(dict(spec, step="first-xray")),
                shaded=_scale_step(dict(spec, step="first-shaded", frames=None)),
                splat_approximation=_scale_step(dict(spec, step="first-splat")),
                whole_file_first=_scale_step(dict(spec, step="first-whole")))


def first_image_file(args) -> Path:
    """``--first-image-file``, or first-image's own: hydrogen ``--size``^3 RGBA, cubic, 3 levels, 5 %, in
    ``--scratch``."""
    return args.first_image_file or args.scratch / f"hydrogen_{args.size}_rgba.clw"


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
