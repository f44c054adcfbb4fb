#!/usr/bin/env python3
"""clwave against its peers: X-ray images of analytic phantoms, time per view and error.

    python tools/compare_peers.py [--phantom hydrogen marschner-lobb] [--size 128 256]
                                  [--image 512] [--views 3] [--keep 0.01 0.05]
                                  [--progressive-keep 0.08] [--steps 4] [--raytrace-keep 0.05]
                                  [--raytrace-tolerance 1e-3] [--raytrace-views 1] [--out out/peers]

Every method renders the same phantom (sampled at the cell centres of an n³ grid, spacing 1)
from the same orthographic views (``clwave.Camera``: golden-angle spiral, image ``--image``²,
extent the volume diagonal):

- ``clwave splat K``: wavelet splatting of the cubic model (3 levels) thresholded to K of
  the voxels; prepare = decomposition + thresholding + upload (kernel build included);
- ``clwave progressive``: the ``--progressive-keep`` model refined in ``--steps`` doubling
  frames into one framebuffer (the first frame holds keep / 2^(steps-1) of the voxels); the
  time of a frame counts from the start of its view;
- ``clwave raytrace K (X-ray, tol T)``: ray tracing in wavelet space (``clwave.RayTracer``,
  ``absorption=False``: the line integral of the same cubic model, knot segment by knot
  segment, within the absolute tolerance T) of the model thresholded to K; prepare =
  decomposition + thresholding + B-spline expansion on the device; a 1-pixel warm-up builds
  the kernel, whose time is reported apart.  At 256³ and 512² a view takes 20-30 s on 2 CPU
  cores, so this row renders only the first ``--raytrace-views`` views (default 1: the row's
  first and median times are that one view; 0 leaves the row out);
- ``NumPy/SciPy``: trilinear ``scipy.ndimage.map_coordinates`` at one sample per voxel
  length along every ray across the whole image extent, summed (what a user would write);
- ``Fourier volume rendering`` (Malzbender 1993; Totsuka & Levoy 1993): one 3-D FFT of the
  volume zero-padded to twice its size and pre-divided by the kernel's transform, then per
  view the central slice interpolated with a Kaiser–Bessel kernel (width 6, the accuracy of a
  non-uniform FFT) and one inverse 2-D FFT;
- ``VTK additive`` and ``VTK composite``: ``vtkFixedPointVolumeRayCastMapper`` offscreen
  (EGL), linear interpolation, sample distance 1 voxel, all cores; additive blending sums
  opacities as 1 - prod(1 - opacity) in 8 bits and composite shades an emission-absorption
  image: neither is a line integral, so their times are speed references only.

Ground truth is the line integral of the phantom's *formula* (``clwave.io.phantoms.analytic``)
over the chord of each ray through the phantom's cube: composite Gauss-Legendre (8 nodes per
segment of at most 8 voxels); the same integral with twice the segments on every 8th row is
reported as its own accuracy.  Error = relative RMS, ||image - truth|| / ||truth|| over the
image.  Each method runs in its own process, whose peak resident memory (Python and imports
included) is reported.

Writes ``comparison.json``, ``comparison.md`` (the table) and ``error_vs_time.png`` into
``--out``.  VTK and matplotlib come with the ``peers`` extra (``pip install .[peers]``); a
missing one is named and its part skipped.
"""

from __future__ import annotations

import argparse
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

TARGET_ERROR = 0.01
GL_NODES = 8        # Gauss-Legendre nodes per ray segment
GL_SEGMENT = 8.0    # longest segment, voxels


def views(count):
    """Distinct views: a golden-angle spiral of azimuths and elevations (as tools/bench.py)."""
    return [(137.508 * i % 360.0, -60.0 + 120.0 * (i + 0.5) / count) for i in range(count)]


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

def run_splat(case, keep):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    renderer = clwave.SplatRenderer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        res = clwave.splat(wv, clwave.Camera(az, el, size=case["image"]), renderer=renderer)
        seconds.append(time.perf_counter() - t)
        images.append(res.image[..., 0])
    return dict(prepare=prepare, seconds=seconds, images=images, compile=renderer.compile_seconds,
                coefficients=wv.kept)


def run_progressive(case, keep, steps):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    renderer = clwave.SplatRenderer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    frames = []
    for az, el in case["views"]:
        cam = clwave.Camera(az, el, size=case["image"])
        frames.append([(f.seconds, f.image[..., 0], f.coefficients / wv.n_voxels)
                       for f in clwave.progressive(wv, cam, steps=steps, renderer=renderer)])
    return dict(prepare=prepare, frames=frames, compile=renderer.compile_seconds)


def run_raytrace(case, keep, tolerance, count):
    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=keep)
    tracer = clwave.RayTracer(wv, device=case["device"])
    prepare = time.perf_counter() - start
    # warm-up on one pixel: builds the X-ray kernel, so the views are timed without it
    warm = tracer.render(clwave.Camera(size=1), tolerance=tolerance, absorption=False)
    seconds, images, segments = [], [], []
    for az, el in case["views"][:count]:
        t = time.perf_counter()
        res = tracer.render(clwave.Camera(az, el, size=case["image"]), tolerance=tolerance, absorption=False)
        seconds.append(time.perf_counter() - t)
        images.append(res.image[..., 0])
        segments.append(res.meta["segments"])
    return dict(prepare=prepare, seconds=seconds, images=images, compile=warm.meta["compile_seconds"],
                expand=tracer.setup_seconds, coefficients=wv.kept, segments=segments, tolerance=tolerance)


def run_numpy(case):
    vol = clwave.phantom(case["phantom"], case["n"])
    data = vol.data
    shape = np.array(data.shape, float)
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        centres, d = rays(vol, clwave.Camera(az, el, size=case["image"]))
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
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        images.append(renderer.render(clwave.Camera(az, el, size=case["image"])))
        seconds.append(time.perf_counter() - t)
    return dict(prepare=prepare, seconds=seconds, images=images)


def run_vtk(case, blend):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL render window)
    import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (the ray caster's display helper)
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPiecewiseFunction
    from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkRenderer, vtkRenderWindow, vtkVolume,
                                             vtkVolumeProperty, vtkWindowToImageFilter)
    from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper

    vol = clwave.phantom(case["phantom"], case["n"])
    start = time.perf_counter()
    nz, ny, nx = vol.shape
    image = vtkImageData()
    image.SetDimensions(nx, ny, nz)
    image.SetSpacing(*vol.spacing[::-1])
    image.SetOrigin(*(np.array(vol.origin) - (np.array([nx, ny, nz]) - 1) / 2.0 * np.array(vol.spacing[::-1])))
    image.GetPointData().SetScalars(numpy_to_vtk(vol.data.ravel(), deep=True))
    top = float(vol.data.max())
    mapper = vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(image)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetSampleDistance(1.0)
    opacity, colour, prop = vtkPiecewiseFunction(), vtkColorTransferFunction(), vtkVolumeProperty()
    if blend == "additive":
        mapper.SetBlendModeToAdditive()
        opacity.AddPoint(0.0, 0.0)
        opacity.AddPoint(top, 0.05)
        colour.AddRGBPoint(0.0, 1.0, 1.0, 1.0)
        colour.AddRGBPoint(top, 1.0, 1.0, 1.0)
    else:
        mapper.SetBlendModeToComposite()
        opacity.AddPoint(0.0, 0.0)
        opacity.AddPoint(0.1 * top, 0.0)
        opacity.AddPoint(top, 0.3)
        colour.AddRGBPoint(0.0, 0.2, 0.3, 1.0)
        colour.AddRGBPoint(top, 1.0, 1.0, 0.9)
        prop.ShadeOn()
    prop.SetScalarOpacity(opacity)
    prop.SetColor(colour)
    prop.SetInterpolationTypeToLinear()
    volume = vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    renderer = vtkRenderer()
    renderer.AddVolume(volume)
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.AddRenderer(renderer)
    H, W = clwave.Camera(size=case["image"]).size
    window.SetSize(W, H)
    prepare = time.perf_counter() - start
    seconds, images = [], []
    for az, el in case["views"]:
        t = time.perf_counter()
        view = clwave.Camera(az, el, size=case["image"]).view(vol)
        camera = renderer.GetActiveCamera()
        camera.ParallelProjectionOn()
        camera.SetFocalPoint(*view.target)
        camera.SetPosition(*(view.target + 2.0 * W * view.pixel * view.n))
        camera.SetViewUp(*view.v)
        camera.SetParallelScale(H * view.pixel / 2.0)
        renderer.ResetCameraClippingRange()
        window.Render()
        grab = vtkWindowToImageFilter()
        grab.SetInput(window)
        grab.ReadFrontBufferOff()
        grab.Update()
        rgb = vtk_to_numpy(grab.GetOutput().GetPointData().GetScalars()).reshape(H, W, -1)[::-1, :, :3]
        seconds.append(time.perf_counter() - t)
        images.append(rgb.mean(axis=-1).astype(np.float32) / 255.0)
    return dict(prepare=prepare, seconds=seconds, images=images, threads=mapper.GetNumberOfThreads(),
                window=type(window).__name__)


#: name -> (function, needs a peer package, computes the line integral)
METHODS = {
    "splat": (run_splat, None, True),
    "progressive": (run_progressive, None, True),
    "raytrace": (run_raytrace, None, True),
    "numpy": (run_numpy, None, True),
    "fourier": (run_fourier, None, True),
    "vtk": (run_vtk, "vtk", False),
}


def _child(method, case, params):
    """Run one method in this (fresh) process; add its peak resident memory."""
    result = METHODS[method][0](case, *params)
    result["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return result


def in_process(method, case, params=()):
    """Run in a fresh process: BrokenProcessPool if it dies (VTK without a working EGL segfaults)."""
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_child, method, case, params).result()


# ----------------------------------------------------------------------------- comparison
def compare(case, args, log) -> tuple:
    """Rows of the table for one phantom and size, the case's figures, and each method's first image."""
    cams = [clwave.Camera(az, el, size=case["image"]) for az, el in case["views"]]
    start = time.perf_counter()
    truths = [ground_truth(case["phantom"], case["n"], cam) for cam in cams]
    check = slice(0, None, 8)
    finer = ground_truth(case["phantom"], case["n"], cams[0], segment=GL_SEGMENT / 2, rows=check)
    case_info = dict(truth_seconds=(time.perf_counter() - start) / len(cams),
                     truth_accuracy=relative_rms(truths[0][check], finer))
    log(f"  ground truth: {case_info['truth_seconds']:.1f} s a view, "
        f"accuracy {case_info['truth_accuracy']:.1e} (against twice the segments)")
    jobs = [(f"clwave splat {k:g}", "splat", (k,)) for k in args.keep]
    jobs += [("clwave progressive", "progressive", (args.progressive_keep, args.steps))]
    if args.raytrace_views:
        jobs.append((f"clwave raytrace {args.raytrace_keep:g} (X-ray, tol {args.raytrace_tolerance:g})", "raytrace",
                     (args.raytrace_keep, args.raytrace_tolerance, args.raytrace_views)))
    jobs += [("NumPy/SciPy map_coordinates", "numpy", ()), ("Fourier volume rendering", "fourier", ())]
    jobs += [(f"VTK {blend}", "vtk", (blend,)) for blend in ("additive", "composite")]
    rows, images = [], {"ground truth": truths[0]}
    for label, method, params in jobs:
        package = METHODS[method][1]
        if package and not _have(package):
            rows.append(dict(method=label, skipped=f"{package} is not installed (pip install .[peers])"))
            log(f"  {label}: skipped, {rows[-1]['skipped']}")
            continue
        try:
            res = in_process(method, case, params)
        except BrokenProcessPool:
            rows.append(dict(method=label, skipped="its process died (VTK without EGL: bash tools/setup.sh --peers)"))
            log(f"  {label}: skipped, {rows[-1]['skipped']}")
            continue
        if method == "progressive":
            rows.extend(_progressive_rows(label, res, truths))
            images[rows[-1]["method"]] = res["frames"][0][-1][1]
        else:
            images[label] = res["images"][0]
            row = dict(method=label, prepare=res["prepare"], first=res["seconds"][0],
                       median=statistics.median(res["seconds"][1:] or res["seconds"]),
                       peak_rss_mib=res["peak_rss_mib"], line_integral=METHODS[method][2],
                       extra={k: v for k, v in res.items() if k not in ("images", "seconds", "prepare")})
            if METHODS[method][2]:
                row["error"] = statistics.median(relative_rms(im, gt) for im, gt in zip(res["images"], truths))
                row["to_target"] = row["median"] if row["error"] <= TARGET_ERROR else None
                row["target_text"] = _target_text(row["to_target"], row["error"])
            rows.append(row)
        log("  " + _row_text(rows[-1]))
    return rows, case_info, images


def _progressive_rows(label, res, truths) -> list:
    """One row per frame; the time to the target error is on the first frame that reaches it."""
    rows = []
    for i in range(len(res["frames"][0])):
        secs = [frames[i][0] for frames in res["frames"]]
        error = statistics.median(relative_rms(frames[i][1], gt) for frames, gt in zip(res["frames"], truths))
        median = statistics.median(secs[1:] or secs)
        rows.append(dict(method=f"{label} {100 * res['frames'][0][i][2]:.3g} %", prepare=res["prepare"] if i == 0
                         else None, first=secs[0], median=median, peak_rss_mib=res["peak_rss_mib"],
                         line_integral=True, error=error, frame=i, kept=res["frames"][0][i][2], target_text=""))
    reached = next((r for r in rows if r["error"] <= TARGET_ERROR), None)
    if reached:
        reached["target_text"] = _target_text(reached["median"], reached["error"])
    else:
        rows[-1]["target_text"] = _target_text(None, min(r["error"] for r in rows))
    for r in rows:
        r["to_target"] = reached["median"] if reached else None
    return rows


def _target_text(seconds, best_error) -> str:
    return f"{seconds:.3g} s" if seconds is not None else f"not reached (best {100 * best_error:.3g} %)"


def _have(package) -> bool:
    import importlib.util
    return importlib.util.find_spec(package) is not None


def _row_text(row) -> str:
    if "skipped" in row:
        return f"{row['method']}: skipped ({row['skipped']})"
    err = f"error {row['error']:.2e}" if "error" in row else "error n/a (not a line integral)"
    return f"{row['method']}: first {row['first']:.3f} s, median {row['median']:.3f} s, {err}, " \
           f"peak {row['peak_rss_mib']:.0f} MiB"


# ----------------------------------------------------------------------------- outputs
def markdown(report) -> str:
    lines = ["| phantom | size | method | prepare s | first view s | median view s | peak RSS MiB "
             "| rel. RMS error | time to 1 % |", "|---|---|---|---|---|---|---|---|---|"]
    for case in report["cases"]:
        for row in case["rows"]:
            head = f"| {case['phantom']} | {case['n']}³ | {row['method']} "
            if "skipped" in row:
                lines.append(head + f"| skipped: {row['skipped']} | | | | | |")
                continue
            prep = "" if row.get("prepare") is None else f"{row['prepare']:.2f}"
            error = f"{100 * row['error']:.3g} %" if "error" in row else "n/a"
            target = row["target_text"] if "error" in row else "speed reference only"
            lines.append(head + f"| {prep} | {row['first']:.3g} | {row['median']:.3g} | {row['peak_rss_mib']:.0f} "
                         f"| {error} | {target} |")
    return "\n".join(lines) + "\n"


def target_lines(report) -> list:
    """The issue's speed target: first progressive frame >= 2x faster than VTK additive."""
    out = []
    for case in report["cases"]:
        first = next((r for r in case["rows"] if r["method"].startswith("clwave progressive")
                      and r.get("frame") == 0), None)
        vtk = next((r for r in case["rows"] if r["method"] == "VTK additive" and "skipped" not in r), None)
        if first and vtk:
            ratio = vtk["median"] / first["median"]
            out.append(f"{case['phantom']} {case['n']}³ at {report['image']}²: first progressive frame "
                       f"({100 * first['kept']:.3g} % kept) {first['median']:.3g} s, "
                       f"VTK additive {vtk['median']:.3g} s: "
                       f"{ratio:.2f}x faster (target 2x: {'met' if ratio >= 2.0 else 'NOT met'})")
    return out


def plot(report, path) -> bool:
    if not _have("matplotlib"):
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.ticker import NullFormatter

    cases = report["cases"]
    phantoms = list(dict.fromkeys(c["phantom"] for c in cases))
    sizes = sorted({c["n"] for c in cases})
    fig, axes = plt.subplots(len(phantoms), len(sizes), figsize=(5.6 * len(sizes), 4.4 * len(phantoms)),
                             squeeze=False)
    for case in cases:
        ax = axes[phantoms.index(case["phantom"]), sizes.index(case["n"])]
        rows = [r for r in case["rows"] if "skipped" not in r]
        prog = [r for r in rows if r["method"].startswith("clwave progressive")]
        if prog:
            ax.plot([r["median"] for r in prog], [r["error"] for r in prog], "o-", color="C0",
                    label="clwave progressive")
            for r in prog:
                ax.annotate(f"{100 * r['kept']:.3g}%", (r["median"], r["error"]), fontsize=7,
                            textcoords="offset points", xytext=(4, 4))
        splats = [r for r in rows if r["method"].startswith("clwave splat")]
        if splats:
            ax.plot([r["median"] for r in splats], [r["error"] for r in splats], "s--", color="C1",
                    label="clwave splat " + ", ".join(r["method"].split()[-1] for r in splats))
        for r in [r for r in rows if r["method"].startswith("clwave raytrace")]:
            ax.plot([r["median"]], [r["error"]], "*", color="C5", markersize=11, label=r["method"])
        for r, style in zip([r for r in rows if r["method"] in ("NumPy/SciPy map_coordinates",
                                                               "Fourier volume rendering")], ("^", "D")):
            ax.plot([r["median"]], [r["error"]], style, markersize=8, label=r["method"])
        for r, colour in zip([r for r in rows if r["method"].startswith("VTK")], ("C3", "C2")):
            ax.axvline(r["median"], color=colour, ls=":", label=f"{r['method']} (time only)")
        ax.axhline(TARGET_ERROR, color="grey", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("seconds per view (median)")
        ax.set_ylabel("relative RMS error vs analytic")
        ax.set_title(f"{case['phantom']} {case['n']}³, {report['image']}²", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def montage(images, title, path) -> bool:
    """First-view images of every method side by side (each windowed to its own range)."""
    if not _have("matplotlib"):
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(images), figsize=(2.3 * len(images), 2.7))
    for ax, (label, image) in zip(np.atleast_1d(axes), images.items()):
        ax.imshow(image, cmap="gray", vmin=0.0, vmax=float(np.percentile(image, 99.9)) or 1.0)
        ax.set_title(label, fontsize=7)
        ax.axis("off")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


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
    parser.add_argument("--device", default="auto")
    parser.add_argument("--out", type=Path, default=Path("out/peers"), help="folder for the outputs")
    args = parser.parse_args(argv)
    if args.views < 1 or args.image < 8 or args.steps < 1:
        parser.error("--views and --steps must be >= 1 and --image >= 8")
    if not 0 <= args.raytrace_views <= args.views:
        parser.error("--raytrace-views must be between 0 and --views")
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
            case = dict(phantom=name, n=n, image=args.image, views=views(args.views), device=args.device)
            rows, info, images = compare(case, args, log)
            report["cases"].append(dict(phantom=name, n=n, rows=rows, **info))
            montage(images, f"{name} {n}³, first view", args.out / f"images_{name}_{n}.png")
    report["seconds"] = time.perf_counter() - started
    report["target"] = target_lines(report)
    (args.out / "comparison.json").write_text(json.dumps(report, indent=2) + "\n")
    table = markdown(report)
    (args.out / "comparison.md").write_text(table + "\n" + "\n".join(f"- {t}" for t in report["target"]) + "\n")
    log("\n" + table)
    for line in report["target"]:
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
