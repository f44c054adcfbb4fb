#!/usr/bin/env python3
"""clwave against its peers: X-ray images of analytic phantoms, and shaded images of the classified ones.

    python tools/compare_peers.py [--phantom hydrogen marschner-lobb] [--size 128 256]
                                  [--image 512] [--views 3] [--keep 0.01 0.05] [--coarse 0.02]
                                  [--progressive-keep 0.08] [--steps 4] [--raytrace-keep 0.05]
                                  [--raytrace-tolerance 1e-3] [--raytrace-views 1] [--tf hydrogen]
                                  [--shaded-keep 0.05 1] [--shaded-tolerance 1e-2]
                                  [--shaded-reference-tolerance 1e-4] [--shaded-views 1] [--post-views 1]
                                  [--vtk-sweep D ...] [--vtk-interpolation linear] [--vtk-resample 1]
                                  [--vtk-window 1] [--sweep-tolerance 1e-2 1e-3] [--sweep-keep 0.05]
                                  [--sweep-rounds 2]
                                  [--skip-xray] [--out out/peers]

Every method renders the same phantom (sampled at the cell centres of an n³ grid, spacing 1)
from the same orthographic views (``clwave.Camera``: golden-angle spiral, image ``--image``²,
centred, extent the volume diagonal):

- ``clwave splat K, renderer reused``: wavelet splatting of the cubic model (3 levels)
  thresholded to K of the voxels, one ``SplatRenderer`` (``coarse=--coarse``) for all views;
  prepare = decomposition + thresholding + upload (kernel build included);
- ``clwave splat K, one-shot clwave.splat``: the call scripts make, ``clwave.splat(wv, camera)``
  each view (the first K of ``--keep``, the same ``coarse``);
- ``clwave progressive``: the ``--progressive-keep`` model refined in ``--steps`` doubling
  frames into one framebuffer (the first frame holds keep / 2^(steps-1) of the voxels); the
  time of a frame counts from the start of its view;
- ``clwave raytrace K (X-ray, tol T)``: ray tracing in wavelet space (``absorption=False``: the
  line integral of the same cubic model within the absolute tolerance T); a 1-pixel warm-up
  builds the kernel; only the first ``--raytrace-views`` views (0 leaves the row out);
- ``NumPy/SciPy``: trilinear ``scipy.ndimage.map_coordinates`` at one sample per voxel
  length along every ray across the whole image extent, summed (what a user would write);
- ``Fourier volume rendering`` (``tools/fvr.py``): real-input FFT of the 2x zero-padded,
  roll-off-compensated volume once, then per view the half-plane central slice by Kaiser-Bessel
  interpolation (width 4, tabulated weights, threads) and one inverse 2-D FFT;
- ``VTK additive``: ``vtkFixedPointVolumeRayCastMapper`` (``tools/peers_vtk.py``), linear interpolation, sample
  distance 1 voxel, all cores; 1 - prod(1 - opacity) in 8 bits: a speed reference only. Only ``Render()`` is timed;
  the read-back is timed apart (``extra.readback``), and the first view (set-up) is reported apart.

Shaded rows (``--shaded-views`` > 0): the phantom classified with the ``--tf`` preset,

- ``clwave raytrace K (shaded, tol T)``: emission-absorption ray tracing with Phong shading
  (one headlight) of the cubic model thresholded to each ``--shaded-keep``;
- ``VTK composite``: the same mapper on the scalar volume with the preset's colours and opacity and clwave's Phong
  light (``tools/peers_vtk.py``); it classifies after interpolating (trilinear), samples at fixed steps, composites
  in 15-bit fixed point and returns 8 bits;
- both compared (RGB) with a float64 clwave ray trace of the full classified model at
  ``--shaded-reference-tolerance``.

Post-classified rows (``--post-views`` > 0): ``clwave raytrace K (post-classified, ...)`` ray traces the *scalar*
model through the same preset at render time (``transfer_function=``), as VTK's composite does with the scalar
volume; both compared with a float64 clwave ray trace of the full scalar model, post-classified (the VTK
composite row then with this reference).  ``--vtk-sweep D ...`` adds, at equal error, clwave's post-classified
render at each ``--sweep-tolerance`` and VTK's composite at each sample distance D × ``--vtk-interpolation`` ×
``--vtk-resample`` × ``--vtk-window``, interleaved in one process (``run_sweep``), against the same reference, and
the headline's time of each side at the other's error (``peers_report.equal_error``).  ``--skip-xray`` leaves out
the X-ray rows and their ground truth.

X-ray ground truth is the line integral of the phantom's *formula* (``clwave.io.phantoms.analytic``)
over the chord of each ray through the phantom's cube: composite Gauss-Legendre (8 nodes per
segment of at most 8 voxels); the same integral with twice the segments on every 8th row is
reported as its own accuracy.  Error = relative RMS, ||image - reference|| / ||reference|| over
the image.  Each method runs in its own process, whose peak resident memory is reported, split
into the Python baseline (interpreter and imports), the prepared model and renderer, and the views.

Writes ``comparison.json``, ``comparison.md`` (the table and the headline ratios clwave / FVR
and clwave / VTK) and ``error_vs_time.png`` into ``--out``.  VTK and matplotlib come with the
``peers`` extra (``pip install .[peers]``); a missing one is named and its part skipped.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import multiprocessing
import os
import resource
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402
from clwave.io.phantoms import analytic  # noqa: E402
from fvr import FourierRenderer  # noqa: E402
from peers_report import (TARGET_ERROR, have, headline, markdown, montage, plot, row_text,  # noqa: E402
                          sweep_rows, target_text)

GL_NODES = 8        # Gauss-Legendre nodes per ray segment
GL_SEGMENT = 8.0    # longest segment, voxels


def views(count):
    """Distinct views: a golden-angle spiral of azimuths and elevations (as tools/bench.py)."""
    return [(137.508 * i % 360.0, -60.0 + 120.0 * (i + 0.5) / count) for i in range(count)]


def camera(case, az, el):
    """The view every method renders: centred on the volume, the image as wide as the volume's diagonal
    (explicit, so that a classified model's smaller content does not zoom its views)."""
    return clwave.Camera(az, el, size=case["image"], target=(0.0, 0.0, 0.0), extent=case["n"] * math.sqrt(3.0))


def rays(vol, camera):
    """Pixel centres (H, W, 3) and the unit direction n of an orthographic view."""
    view = camera.view(vol)
    return view.pixel_centres(), view.n


# ----------------------------------------------------------------------------- ground truth
def ground_truth(name, n, camera, segment=GL_SEGMENT, rows=None) -> np.ndarray:
    """Line integrals of the analytic phantom over each ray's chord through the phantom cube."""
    f = analytic(name, n)
    view = camera.view(_Grid(n))
    centres = view.pixel_centres()
    if rows is not None:
        centres = centres[rows]
    d = view.n
    half = n / 2.0  # the phantom cube [-D, D]^3 is world [-n/2, n/2]^3
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(d != 0, (centres + half) / d, -np.inf)  # p - t d = -half
        hi = np.where(d != 0, (centres - half) / d, np.inf)
        t0 = np.max(np.minimum(lo, hi), axis=-1)
        t1 = np.min(np.maximum(lo, hi), axis=-1)
        inside_axis = np.all((d != 0) | (np.abs(centres) <= half), axis=-1)
    t0 = np.where(inside_axis, t0, 0.0)
    t1 = np.where(inside_axis & (t1 > t0), t1, t0)
    segments = max(1, math.ceil(float(np.max(t1 - t0, initial=0.0)) / segment))
    x, w = np.polynomial.legendre.leggauss(GL_NODES)
    s = ((np.arange(segments)[:, None] + (x[None, :] + 1.0) / 2.0) / segments).ravel()  # (S*Q,) in [0, 1]
    ws = np.tile(w / 2.0, segments) / segments
    out = np.zeros(centres.shape[:2])
    for r in range(centres.shape[0]):
        length = (t1[r] - t0[r])[:, None]
        t = t0[r][:, None] + length * s[None, :]                       # (W, S*Q)
        pts = centres[r][:, None, :] - t[..., None] * d                # (W, S*Q, 3)
        out[r] = np.sum(f(pts) * ws[None, :], axis=1) * length[:, 0]
    return out


class _Grid:
    """The shape/spacing/origin a camera needs for an n³ phantom."""

    def __init__(self, n):
        self.shape, self.spacing, self.origin = (n, n, n), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)


def relative_rms(image, truth) -> float:
    return float(np.sqrt(np.sum((image - truth) ** 2) / np.sum(truth ** 2)))


# ----------------------------------------------------------------------------- methods
# Each method gets the case (phantom, n, image size, views, options) and returns
# dict(prepare=seconds, seconds=[per view], images=[per view (H, W)], plus extras);
# progressive methods return frames=[per view: [(seconds, image), ...]].

def run_splat(case, keep, coarse, oneshot):
    """``oneshot``: ``clwave.splat(wv, camera)`` each view (the call scripts make), else one SplatRenderer reused."""
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    renderer = None if oneshot else clwave.SplatRenderer(wv, device=case["device"], coarse=coarse)
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        res = clwave.splat(wv, camera(case, az, el), device=case["device"], coarse=coarse,
                           renderer=renderer)
        seconds.append(time.perf_counter() - t)
        images.append(res.image[..., 0])
    return dict(prepare=prepare, seconds=seconds, images=images, coefficients=wv.kept, model_peak=model_peak)


def run_progressive(case, keep, steps):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    renderer = clwave.SplatRenderer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    frames = []
    for az, el in case["views"]:
        cam = camera(case, az, el)
        frames.append([(f.seconds, f.image[..., 0], f.coefficients / wv.n_voxels)
                       for f in clwave.progressive(wv, cam, steps=steps, renderer=renderer)])
    return dict(prepare=prepare, frames=frames, compile=renderer.compile_seconds, model_peak=model_peak)


def run_raytrace(case, keep, tolerance, count):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    tracer = clwave.RayTracer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    # warm-up on one pixel: builds the X-ray kernel, so the views are timed without it
    warm = tracer.render(clwave.Camera(size=1), tolerance=tolerance, absorption=False)
    seconds, images, segments = [], [], []
    for az, el in case["views"][:count]:
        t = time.perf_counter()
        res = tracer.render(camera(case, az, el), tolerance=tolerance, absorption=False)
        seconds.append(time.perf_counter() - t)
        images.append(res.image[..., 0])
        segments.append(res.meta["segments"])
    return dict(prepare=prepare, seconds=seconds, images=images, compile=warm.meta["compile_seconds"],
                expand=tracer.setup_seconds, coefficients=wv.kept, segments=segments, tolerance=tolerance,
                model_peak=model_peak)


def run_numpy(case):
    vol = clwave.phantom(case["phantom"], case["n"])
    data = vol.data
    shape = np.array(data.shape, float)
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        centres, d = rays(vol, camera(case, az, el))
        radius = float(np.linalg.norm(shape)) / 2.0
        steps = np.arange(-radius, radius + 0.5, 1.0)                  # one sample per voxel length
        image = np.empty(centres.shape[:2], np.float32)
        for r in range(centres.shape[0]):
            pts = centres[r][:, None, :] - steps[None, :, None] * d      # (W, S, 3) world x, y, z
            index = pts[..., ::-1] + (shape - 1.0) / 2.0                 # (z, y, x) voxel indices
            samples = ndimage.map_coordinates(data, index.reshape(-1, 3).T, order=1, mode="constant", cval=0.0)
            image[r] = samples.reshape(pts.shape[:2]).sum(axis=1)
        seconds.append(time.perf_counter() - t)
        images.append(image)
    return dict(prepare=0.0, seconds=seconds, images=images)


def run_fourier(case):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    renderer = FourierRenderer(vol)
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        images.append(renderer.render(camera(case, az, el)))
        seconds.append(time.perf_counter() - t)
    return dict(prepare=prepare, seconds=seconds, images=images, spectrum_mib=renderer.nbytes / 2**20,
                model_peak=model_peak)


def run_shaded(case, keep, tolerance, precision, count, classification="pre"):
    """Shaded emission-absorption ray tracing of the phantom under the ``--tf`` preset, first ``count`` views:
    ``classification`` "pre" classifies the voxels before the transform (the RGBA model), "post" ray traces the
    scalar model through the transfer function (docs/raytracing.md §10); prepare = decomposition + thresholding
    + expansion; a 1-pixel warm-up builds the kernel."""
    tf = clwave.TransferFunction.preset(case["tf"])
    vol = clwave.phantom(case["phantom"], case["n"])
    vol = tf.classify(vol) if classification == "pre" else vol
    extra = dict(transfer_function=tf) if classification == "post" else {}
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3)
    wv = wv.threshold(keep=keep) if keep < 1 else wv
    tracer = clwave.RayTracer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    warm = tracer.render(clwave.Camera(size=1), tolerance=tolerance, precision=precision, **extra)
    seconds, images = [], []
    for az, el in case["views"][:count]:
        t = time.perf_counter()
        res = tracer.render(camera(case, az, el), tolerance=tolerance, precision=precision, **extra)
        seconds.append(time.perf_counter() - t)
        images.append(res.image[..., :3])
    return dict(prepare=prepare, seconds=seconds, images=images, compile=warm.meta["compile_seconds"],
                model_peak=model_peak, tolerance=tolerance, precision=precision, coefficients=wv.kept,
                classification=classification, pool_bytes=tracer.bricks.pool_bytes)


def run_vtk(case, blend):
    """VTK's CPU ray caster at its defaults (tools/peers_vtk.py: the voxels, trilinear, sample distance 1, 8 bits):
    ``additive`` (a speed reference, not a line integral) or ``composite`` (shaded, the ``--tf`` preset); only
    ``Render()`` timed, the read-back apart, the first view (set-up) reported apart."""
    from peers_vtk import VtkScene

    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    scene = VtkScene(vol, case["image"], blend, tf=clwave.TransferFunction.preset(case["tf"]))
    prepare = time.perf_counter() - start
    model_peak = _peak_mib()
    seconds, readback, images = [], [], []
    for az, el in case["views"]:
        t, r, rgb = scene.render(camera(case, az, el).view(vol))
        seconds.append(t)
        readback.append(r)
        images.append(rgb.mean(axis=-1) if blend == "additive" else rgb)
    return dict(prepare=prepare, seconds=seconds, images=images, readback=readback, model_peak=model_peak,
                threads=scene.mapper.GetNumberOfThreads(), window=type(scene.window).__name__)


def run_sweep(case, keep, tolerances, settings, count, rounds):
    """clwave's post-classified ray trace at each tolerance and VTK's composite at each setting (sample distance,
    interpolation, resample factor, final colour window: tools/peers_vtk.py), in this one process over the first
    ``count`` views, interleaved ``rounds`` times (clwave's tolerances, then VTK's settings, view by view), so that
    their ratios see the same load; each VTK scene (one a volume and interpolation) renders the first view
    once untimed (its set-up: the resampling, gradients), clwave a pixel (the kernel's build). Images are the first
    round's. A window "auto" is one 8-bit step over the brightest pixel of the scene's untimed renders."""
    from peers_vtk import VtkScene

    tf = clwave.TransferFunction.preset(case["tf"])
    vol = clwave.phantom(case["phantom"], case["n"])
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3)
    tracer = clwave.RayTracer(wv.threshold(keep=keep) if keep < 1 else wv, device=case["device"])
    for tol in tolerances:
        tracer.render(clwave.Camera(size=1), tolerance=tol, transfer_function=tf)
    views = [camera(case, az, el).view(vol) for az, el in case["views"][:count]]
    scenes, prepare, top = {}, {}, {}
    for _, interpolation, resample, _ in settings:  # one scene a volume and interpolation
        if (interpolation, resample) not in scenes:
            start = time.perf_counter()
            scene = scenes[interpolation, resample] = VtkScene(vol, case["image"], tf=tf, interpolation=interpolation,
                                                               resample=resample)
            top[interpolation, resample] = max(float(scene.render(view)[2].max()) for view in views)
            prepare[interpolation, resample] = time.perf_counter() - start
    # the "auto" window: the brightest pixel of the scene's views at the default window, one 8-bit step above it
    settings = [(d, i, f, min(1.0, top[i, f] + 1 / 255) if w == "auto" else w) for d, i, f, w in settings]
    model_peak = _peak_mib()
    jobs = [("clwave", tol) for tol in tolerances] + [("vtk", s) for s in settings]
    seconds, images = {job: [] for job in jobs}, {job: [] for job in jobs}
    for r in range(rounds):
        for az_el, view in zip(case["views"], views):
            for side, what in jobs:
                if side == "clwave":
                    t = time.perf_counter()
                    image = tracer.render(camera(case, *az_el), tolerance=what, transfer_function=tf).image[..., :3]
                    elapsed = time.perf_counter() - t
                else:
                    scene = scenes[what[1:3]]
                    scene.set(what[0], what[3])
                    elapsed, _, image = scene.render(view)
                seconds[(side, what)].append(elapsed)
                if r == 0:
                    images[(side, what)].append(image)
    return dict(jobs=[dict(side=side, setting=what, seconds=seconds[(side, what)], images=images[(side, what)],
                           prepare=prepare.get(what[1:3]) if side == "vtk" else None) for side, what in jobs],
                keep=keep, rounds=rounds, model_peak=model_peak)


#: name -> (function, the peer package it needs, runs on OpenCL)
METHODS = {
    "splat": (run_splat, None, True),
    "progressive": (run_progressive, None, True),
    "raytrace": (run_raytrace, None, True),
    "numpy": (run_numpy, None, False),
    "fourier": (run_fourier, None, False),
    "shaded": (run_shaded, None, True),
    "vtk": (run_vtk, "vtk", False),
    "sweep": (run_sweep, "vtk", True),
}


def _peak_mib() -> float:
    """Peak resident memory of this process image (VmHWM: unlike ru_maxrss, not inherited across exec from the
    parent that spawned it)."""
    try:
        with open("/proc/self/status") as fh:
            return next(float(line.split()[1]) for line in fh if line.startswith("VmHWM:")) / 1024.0
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _child(method, case, params):
    """Run one method in this (fresh) process; add its peak resident memory, and how much of it is the Python
    baseline (interpreter, NumPy, SciPy, clwave; the OpenCL runtime for clwave's methods), the prepared model and
    renderer, and the views."""
    if METHODS[method][2]:
        clwave.ComputeContext.get(case["device"])
    base = _peak_mib()
    result = METHODS[method][0](case, *params)
    result["peak_rss_mib"] = _peak_mib()
    model = result.pop("model_peak", base)
    result["memory_mib"] = dict(baseline=base, model=model - base, views=result["peak_rss_mib"] - model)
    return result


def in_process(method, case, params=()):
    """Run in a fresh process: BrokenProcessPool if it dies (VTK without a working EGL segfaults)."""
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_child, method, case, params).result()


# ----------------------------------------------------------------------------- comparison
def compare(case, args, log) -> tuple:
    """Rows of the table for one phantom and size, the case's figures, and each method's first image.

    X-ray rows are compared with the analytic line integrals; shaded rows (clwave's ray tracing and VTK's
    composite, the ``--tf`` classification) with a float64 clwave ray trace of the full classified model."""
    cams = [camera(case, az, el) for az, el in case["views"]]
    references, case_info = {}, {}
    if not args.skip_xray:
        start = time.perf_counter()
        truths = [ground_truth(case["phantom"], case["n"], cam) for cam in cams]
        check = slice(0, None, 8)
        finer = ground_truth(case["phantom"], case["n"], cams[0], segment=GL_SEGMENT / 2, rows=check)
        case_info = dict(truth_seconds=(time.perf_counter() - start) / len(cams),
                         truth_accuracy=relative_rms(truths[0][check], finer))
        log(f"  ground truth: {case_info['truth_seconds']:.1f} s a view, "
            f"accuracy {case_info['truth_accuracy']:.1e} (against twice the segments)")
        references["truth"] = truths
    jobs = [(f"clwave splat {k:g}, renderer reused", "splat", (k, args.coarse, False), "truth") for k in args.keep]
    jobs += [(f"clwave splat {args.keep[0]:g}, one-shot clwave.splat", "splat", (args.keep[0], args.coarse, True),
              "truth")]
    jobs += [("clwave progressive", "progressive", (args.progressive_keep, args.steps), "truth")]
    if args.raytrace_views:
        jobs.append((f"clwave raytrace {args.raytrace_keep:g} (X-ray, tol {args.raytrace_tolerance:g})", "raytrace",
                     (args.raytrace_keep, args.raytrace_tolerance, args.raytrace_views), "truth"))
    jobs += [("NumPy/SciPy map_coordinates", "numpy", (), "truth"),
             ("Fourier volume rendering", "fourier", (), "truth")]
    if args.skip_xray:
        jobs = []
    else:
        jobs += [("VTK additive", "vtk", ("additive",), None)]
    if args.shaded_views:
        jobs.append((f"shaded reference (clwave raytrace, float64, tol {args.shaded_reference_tolerance:g})", "shaded",
                     (1.0, args.shaded_reference_tolerance, "double", args.shaded_views), "reference"))
        jobs += [(f"clwave raytrace {k:g} (shaded, tol {args.shaded_tolerance:g})", "shaded",
                  (k, args.shaded_tolerance, "single", args.shaded_views), "shaded") for k in args.shaded_keep]
    if args.post_views:  # both post-classified: the scalar volume through the transfer function
        jobs.append((f"post-classified reference (clwave raytrace, float64, tol {args.shaded_reference_tolerance:g})",
                     "shaded", (1.0, args.shaded_reference_tolerance, "double", args.post_views, "post"), "reference"))
        jobs += [(f"clwave raytrace {k:g} (post-classified, shaded, tol {args.shaded_tolerance:g})", "shaded",
                  (k, args.shaded_tolerance, "single", args.post_views, "post"), "shaded") for k in args.shaded_keep]
    compared = "shaded" if args.shaded_views or args.post_views else None  # the last reference: post's if made
    jobs += [(f"VTK composite (shaded, {args.tf})", "vtk", ("composite",), compared)]
    if args.vtk_sweep:  # at equal error: clwave's tolerances and VTK's settings, interleaved in one process
        settings = list(itertools.product(args.vtk_sweep, args.vtk_interpolation, args.vtk_resample, args.vtk_window))
        jobs.append(("sweep", "sweep", (args.sweep_keep, args.sweep_tolerance, settings, args.post_views,
                                        args.sweep_rounds), "shaded"))
    rows, images = [], {"ground truth": references["truth"][0]} if "truth" in references else {}
    for label, method, params, reference in jobs:
        package = METHODS[method][1]
        if package and not have(package):
            rows.append(dict(method=label, skipped=f"{package} is not installed (pip install .[peers])"))
            log(f"  {label}: skipped, {rows[-1]['skipped']}")
            continue
        try:
            res = in_process(method, case, params)
        except BrokenProcessPool:
            rows.append(dict(method=label, skipped="its process died (VTK without EGL: bash tools/setup.sh --peers)"))
            log(f"  {label}: skipped, {rows[-1]['skipped']}")
            continue
        if method == "sweep":
            rows.extend(sweep_rows(res, references["shaded"], relative_rms))
            for row in rows[-len(res["jobs"]):]:
                log("  " + row_text(row))
            # VTK's 8-bit output alone: the reference over [0, W] rounded to 8 bits (its error floor's first part)
            windows = {r["sweep"]["window"] for r in rows[-len(res["jobs"]):] if r["sweep"]["side"] == "vtk"}
            case_info["eight_bit_error"] = {f"{w:.3g}": statistics.median(relative_rms(
                np.round(np.clip(ref / w, 0, 1) * 255) * (w / 255), ref) for ref in references["shaded"])
                for w in sorted(windows)}
            continue
        if method == "progressive":
            rows.extend(_progressive_rows(label, res, truths, res["memory_mib"]))
            images[rows[-1]["method"]] = res["frames"][0][-1][1]
            log("  " + row_text(rows[-1]))
            continue
        images[label] = res["images"][0] if res["images"][0].ndim == 2 else np.clip(res["images"][0], 0, 1)
        row = dict(method=label, kind="shaded" if reference in ("shaded", "reference") else "xray",
                   prepare=res["prepare"], first=res["seconds"][0],
                   median=statistics.median(res["seconds"][1:] or res["seconds"]), peak_rss_mib=res["peak_rss_mib"],
                   memory_mib=res["memory_mib"],
                   extra={k: v for k, v in res.items() if k not in ("images", "seconds", "prepare", "memory_mib")})
        if reference == "reference":
            references["shaded"] = res["images"]
        elif reference in references:
            pairs = list(zip(res["images"], references[reference]))
            row["error"] = statistics.median(relative_rms(im, ref) for im, ref in pairs)
            row["to_target"] = row["median"] if row["error"] <= TARGET_ERROR else None
            row["target_text"] = target_text(row["to_target"], row["error"])
        rows.append(row)
        log("  " + row_text(rows[-1]))
    return rows, case_info, images


def _progressive_rows(label, res, truths, memory) -> list:
    """One row per frame; the time to the target error is on the first frame that reaches it."""
    rows = []
    for i in range(len(res["frames"][0])):
        secs = [frames[i][0] for frames in res["frames"]]
        error = statistics.median(relative_rms(frames[i][1], gt) for frames, gt in zip(res["frames"], truths))
        median = statistics.median(secs[1:] or secs)
        rows.append(dict(method=f"{label} {100 * res['frames'][0][i][2]:.3g} %", prepare=res["prepare"] if i == 0
                         else None, first=secs[0], median=median, peak_rss_mib=res["peak_rss_mib"],
                         memory_mib=memory, kind="xray", error=error, frame=i, kept=res["frames"][0][i][2],
                         target_text=""))
    reached = next((r for r in rows if r["error"] <= TARGET_ERROR), None)
    if reached:
        reached["target_text"] = target_text(reached["median"], reached["error"])
    else:
        rows[-1]["target_text"] = target_text(None, min(r["error"] for r in rows))
    for r in rows:
        r["to_target"] = reached["median"] if reached else None
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--phantom", nargs="+", default=["hydrogen", "marschner-lobb"])
    parser.add_argument("--size", type=int, nargs="+", default=[128, 256], help="phantom voxels per axis")
    parser.add_argument("--image", type=int, default=512, help="image width and height in pixels")
    parser.add_argument("--views", type=int, default=3, help="distinct views (the first is timed apart)")
    parser.add_argument("--keep", type=float, nargs="+", default=[0.01, 0.05], help="kept fractions to splat")
    parser.add_argument("--progressive-keep", type=float, default=0.08,
                        help="kept fraction refined progressively (the last frame)")
    parser.add_argument("--steps", type=int, default=4, help="progressive frames, doubling")
    parser.add_argument("--raytrace-keep", type=float, default=0.05, help="kept fraction to ray trace (X-ray mode)")
    parser.add_argument("--raytrace-tolerance", type=float, default=1e-3,
                        help="absolute error allowed on each ray-traced line integral")
    parser.add_argument("--raytrace-views", type=int, default=1,
                        help="views ray traced (the first ones; 20-30 s each at 256^3, 512^2; 0: no ray tracing)")
    parser.add_argument("--coarse", type=float, default=2e-2,
                        help="splat rows: coarse framebuffers for bands this small (SplatRenderer coarse=)")
    parser.add_argument("--tf", default="hydrogen", help="transfer-function preset of the shaded rows")
    parser.add_argument("--shaded-keep", type=float, nargs="+", default=[0.05, 1.0],
                        help="kept fractions ray traced shaded")
    parser.add_argument("--shaded-tolerance", type=float, default=1e-2, help="tolerance of the shaded ray traces")
    parser.add_argument("--shaded-reference-tolerance", type=float, default=1e-4,
                        help="tolerance of the float64 reference ray trace (the full classified model)")
    parser.add_argument("--shaded-views", type=int, default=1,
                        help="views ray traced shaded, and the VTK composite views compared (0: no shaded errors)")
    parser.add_argument("--post-views", type=int, default=1,
                        help="views ray traced post-classified (the scalar model through --tf), with their own float64 "
                             "reference that the VTK composite views are then compared with (0: none)")
    parser.add_argument("--vtk-sweep", type=float, nargs="*", default=[], metavar="DISTANCE",
                        help="VTK sample distances (world units) swept against clwave at equal error, in one process "
                             "with the clwave tolerances --sweep-tolerance, interleaved (needs --post-views >= 1)")
    parser.add_argument("--vtk-interpolation", nargs="+", default=["linear"], choices=["linear", "nearest"],
                        help="the sweep's VTK interpolations (its CPU ray caster has no cubic)")
    parser.add_argument("--vtk-resample", type=int, nargs="+", default=[1],
                        help="the sweep's volumes: 1 the voxels, F the cubic B-spline resampled F times finer")
    parser.add_argument("--vtk-window", type=lambda w: w if w == "auto" else float(w), nargs="+", default=[1.0],
                        help="the sweep's final colour windows, [0, W] onto VTK's 8 bits ('auto': its brightest pixel)")
    parser.add_argument("--sweep-tolerance", type=float, nargs="+", default=[1e-2, 1e-3],
                        help="the sweep's clwave tolerances (post-classified)")
    parser.add_argument("--sweep-keep", type=float, default=0.05, help="kept fraction of the sweep's clwave model")
    parser.add_argument("--sweep-rounds", type=int, default=2, help="times the sweep renders each setting and view")
    parser.add_argument("--skip-xray", action="store_true", help="only the shaded rows (no X-ray rows or truth)")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--out", type=Path, default=Path("out/peers"), help="folder for the outputs")
    args = parser.parse_args(argv)
    if args.views < 1 or args.image < 8 or args.steps < 1:
        parser.error("--views and --steps must be >= 1 and --image >= 8")
    if not all(0 <= k <= args.views for k in (args.raytrace_views, args.shaded_views, args.post_views)):
        parser.error("--raytrace-views, --shaded-views and --post-views must be between 0 and --views")
    if args.vtk_sweep and not (args.post_views and args.sweep_rounds >= 1 and min(args.vtk_sweep) > 0
                               and min(args.vtk_resample) >= 1 and all(w == "auto" or w > 0 for w in args.vtk_window)):
        parser.error("--vtk-sweep needs --post-views >= 1 (its reference), --sweep-rounds >= 1, and distances, "
                     "resample factors (>= 1) and windows above 0")
    if not isinstance(clwave.TransferFunction.preset(args.tf).window, tuple):
        parser.error(f"--tf {args.tf}: VTK needs a preset with a fixed window")
    args.out.mkdir(parents=True, exist_ok=True)
    log = lambda text: print(text, flush=True)  # noqa: E731
    report = dict(machine=dict(cpu=_cpu(), cores=os.cpu_count(), load_average=os.getloadavg(),
                               python=sys.version.split()[0], numpy=np.__version__),
                  device=clwave.ComputeContext.get(args.device).describe(), image=args.image,
                  views=views(args.views), cases=[])
    started = time.perf_counter()
    for name in args.phantom:
        for n in args.size:
            log(f"{name} {n}^3 at {args.image}^2, {args.views} views")
            case = dict(phantom=name, n=n, image=args.image, views=views(args.views), device=args.device, tf=args.tf)
            rows, info, images = compare(case, args, log)
            report["cases"].append(dict(phantom=name, n=n, rows=rows, **info))
            montage(images, f"{name} {n}³, first view", args.out / f"images_{name}_{n}.png")
    report["seconds"] = time.perf_counter() - started
    report["headline"] = headline(report)
    (args.out / "comparison.json").write_text(json.dumps(report, indent=2) + "\n")
    table = markdown(report)
    (args.out / "comparison.md").write_text(table + "\n" + "\n".join(f"- {t}" for t in report["headline"]) + "\n")
    log("\n" + table)
    for line in report["headline"]:
        log(line)
    if not plot(report, args.out / "error_vs_time.png"):
        log("matplotlib is not installed (pip install .[peers]): no plot or image montage")
    log(f"written to {args.out}/ in {report['seconds']:.0f} s")


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            return next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        return "unknown"


if __name__ == "__main__":
    main()
