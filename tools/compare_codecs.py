#!/usr/bin/env python3
"""Rate against distortion: ``.clw`` files beside zfp and SZ3 at the same sizes (docs/codecs.md).

    python tools/compare_codecs.py [--volumes hydrogen marschner-lobb shepp-logan mni152] [--size 128]
                                   [--keep 0.005 0.01 0.02 0.05 0.1 0.2] [--wavelet cubic] [--levels 3]
                                   [--out docs/figures] [--figure docs/figures/rate_distortion.png]

Volumes: the phantoms (``clwave.phantom``, ``--size``³; Shepp-Logan is the CT-like one, piecewise constant
attenuation) and ``mni152``, the MNI152 T1 template of the nilearn wheel at its own 197 x 233 x 189 (skipped,
and said so, without nilearn).  Per keep fraction K, the model of ``--wavelet``/``--levels`` thresholded to K:

- ``.clw float``: ``save(path)``, the float32 values (deflate);
- ``.clw quantised``: ``save(path, quantise="auto")`` (docs/codecs.md §1);
- ``zfp fixed-rate``: zfpy at the rate (bits per voxel) of the quantised ``.clw`` file (none below
  ``ZFP_MIN_RATE``);
- ``zfp fixed-accuracy`` and ``SZ3`` (pysz, absolute error bound): the tolerance bisected so the stream is as
  large as the quantised ``.clw`` file (within 2 %, or the nearest reached).

Every codec compresses the float32 voxels and is measured on what it decodes: the bytes it wrote (the whole
``.clw`` file, HDF5 and content mask included; zfp's and SZ3's streams with their headers), RMSE and maximum
error over the voxels, PSNR = 20 log10(range / RMSE) with the volume's value range, and the error of an X-ray:
the relative RMS difference of the line integrals along z of the approximating model of the decoded voxels
(exactly their sums along z, docs/model.md §4) against those of the original.  Writes ``rate_distortion.json``
and ``rate_distortion.md`` (the table) into ``--out`` and the plot (bits per voxel against PSNR, a panel a
volume) to ``--figure``.  zfpy, pysz and matplotlib come with the ``codecs`` extra; a missing one is named
and its part skipped.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout

import clwave  # noqa: E402

PHANTOMS = ("hydrogen", "marschner-lobb", "shepp-logan")
ZFP_MIN_RATE = 9 / 64  # zfpy's fixed rate needs 9 bits a 4x4x4 block of float32; below, it corrupts its heap
MATCH = 0.02  # bisection stops within this relative size of the target
ITERATIONS = 40


def load(name, size):
    if name in PHANTOMS:
        return clwave.phantom(name, size)
    if importlib.util.find_spec("nilearn") is None:
        return None
    sys.path.insert(0, str(ROOT / "tools"))
    from figures import default_scan  # the MNI152 T1 template inside the nilearn wheel

    return clwave.load(default_scan())


def measure(original, decoded, nbytes) -> dict:
    """Size and errors of ``decoded`` voxels against ``original`` (module docstring)."""
    diff = decoded.astype(np.float64) - original
    rmse = float(np.sqrt(np.mean(diff ** 2)))
    span = float(original.max() - original.min())
    xray = original.sum(axis=0, dtype=np.float64)
    return dict(bytes=int(nbytes), bits_per_voxel=8.0 * nbytes / original.size, rmse=rmse,
                max_error=float(np.abs(diff).max()), psnr=20 * math.log10(span / rmse) if rmse > 0 else math.inf,
                xray_error=float(np.linalg.norm(diff.sum(axis=0)) / np.linalg.norm(xray)))


def clw_rows(vol, args, work) -> list:
    model = clwave.WaveletVolume.from_volume(vol, args.wavelet, levels=args.levels)
    rows = []
    for keep in args.keep:
        kept = model.threshold(keep=keep)
        for codec, quantise in ((".clw float", None), (".clw quantised", "auto")):
            path = work / f"{keep}.clw"
            start = time.perf_counter()
            kept.save(path, overwrite=True, quantise=quantise)
            seconds = time.perf_counter() - start
            decoded = clwave.WaveletVolume.open(path).reconstruct().data
            rows.append(dict(codec=codec, keep=keep, parameter=quantise or "float32", seconds=seconds,
                             **measure(vol.data, decoded, path.stat().st_size)))
    return rows


def matched(encode, target, lo, hi) -> tuple:
    """Bisect a tolerance in [lo, hi] (larger: smaller streams) for a stream of ``target`` bytes; returns
    ``(tolerance, stream)`` nearest the target."""
    best = None
    for _ in range(ITERATIONS):
        mid = math.sqrt(lo * hi)
        stream = encode(mid)
        if best is None or abs(len(stream) - target) < abs(len(best[1]) - target):
            best = (mid, stream)
        if abs(len(stream) - target) <= MATCH * target:
            break
        lo, hi = (mid, hi) if len(stream) > target else (lo, mid)
    return best


def peer_rows(vol, targets, log) -> list:
    data = np.ascontiguousarray(vol.data, dtype=np.float32)
    span = float(data.max() - data.min())
    codecs = {}
    if importlib.util.find_spec("zfpy"):
        import zfpy

        codecs["zfp fixed-rate"] = ("rate", lambda rate: zfpy.compress_numpy(data, rate=rate), zfpy.decompress_numpy)
        codecs["zfp fixed-accuracy"] = ("tolerance", lambda tol: zfpy.compress_numpy(data, tolerance=tol),
                                        zfpy.decompress_numpy)
    else:
        log("zfpy is not installed (pip install .[codecs]): the zfp rows are skipped")
    if importlib.util.find_spec("pysz"):
        from pysz import sz, szConfig, szErrorBoundMode

        def sz3(bound):
            config = szConfig(data.shape)
            config.errorBoundMode, config.absErrorBound = szErrorBoundMode.ABS, bound
            return sz.compress(data, config)[0].tobytes()

        codecs["SZ3"] = ("absolute bound", sz3,
                         lambda stream: sz.decompress(np.frombuffer(stream, np.uint8), np.float32, data.shape)[0])
    else:
        log("pysz is not installed (pip install .[codecs]): the SZ3 rows are skipped")
    rows = []
    for keep, target in targets:
        for codec, (name, encode, decode) in codecs.items():
            start = time.perf_counter()
            if codec == "zfp fixed-rate":
                value = 8.0 * target / data.size
                if value < ZFP_MIN_RATE:
                    log(f"  {100 * keep:g} %: zfp fixed-rate cannot go below {ZFP_MIN_RATE:.3f} bits per voxel")
                    continue
                stream = encode(value)
            else:
                value, stream = matched(encode, target, span * 1e-9, span * 1e3)
            seconds = time.perf_counter() - start
            rows.append(dict(codec=codec, keep=keep, parameter=f"{name} {value:.4g}", seconds=seconds,
                             **measure(vol.data, decode(stream), len(stream))))
    return rows


def table(rows) -> str:
    lines = ["| volume | voxels | keep | codec | parameter | bits/voxel | PSNR dB | RMSE | max error | X-ray error |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['volume']} | {r['shape']} | {100 * r['keep']:g} % | {r['codec']} | {r['parameter']} | "
                     f"{r['bits_per_voxel']:.3f} | {r['psnr']:.1f} | {r['rmse']:.3g} | {r['max_error']:.3g} | "
                     f"{r['xray_error']:.2e} |")
    return "\n".join(lines) + "\n"


def plot(rows, volumes, path, log):
    if importlib.util.find_spec("matplotlib") is None:
        log("matplotlib is not installed (pip install .[codecs]): no plot")
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(volumes), figsize=(4.2 * len(volumes), 3.8), squeeze=False)
    styles = {".clw float": "o-", ".clw quantised": "s-", "zfp fixed-rate": "^--", "zfp fixed-accuracy": "v--",
              "SZ3": "d--"}
    for ax, volume in zip(axes[0], volumes):
        for codec, style in styles.items():
            mine = sorted((r for r in rows if r["volume"] == volume and r["codec"] == codec),
                          key=lambda r: r["bits_per_voxel"])
            if mine:
                ax.plot([r["bits_per_voxel"] for r in mine], [r["psnr"] for r in mine], style, label=codec, ms=4)
        ax.set_xscale("log")
        ax.set_title(f"{volume} {next(r['shape'] for r in rows if r['volume'] == volume)}")
        ax.set_xlabel("bits per voxel")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("PSNR (dB)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--volumes", nargs="+", default=[*PHANTOMS, "mni152"], choices=[*PHANTOMS, "mni152"])
    parser.add_argument("--size", type=int, default=128, help="phantom edge in voxels")
    parser.add_argument("--keep", type=float, nargs="+", default=[0.005, 0.01, 0.02, 0.05, 0.1, 0.2])
    parser.add_argument("--wavelet", default="cubic")
    parser.add_argument("--levels", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "rate_distortion.png")
    args = parser.parse_args(argv)
    log = print
    rows, volumes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.volumes:
            vol = load(name, args.size)
            if vol is None:
                log(f"{name}: the MNI152 template comes with nilearn (pip install .[figures]); skipped")
                continue
            shape = " x ".join(map(str, vol.shape[::-1]))
            log(f"{name} ({shape})")
            mine = clw_rows(vol, args, Path(tmp))
            targets = [(r["keep"], r["bytes"]) for r in mine if r["codec"] == ".clw quantised"]
            mine += peer_rows(vol, targets, log)
            mine.sort(key=lambda r: (r["keep"], r["codec"]))
            for r in mine:
                r.update(volume=name, shape=shape)
                log(f"  {100 * r['keep']:5g} % {r['codec']:20s} {r['bits_per_voxel']:7.3f} bits/voxel  "
                    f"PSNR {r['psnr']:6.1f} dB  X-ray {r['xray_error']:.2e}")
            rows += mine
            volumes.append(name)
    args.out.mkdir(parents=True, exist_ok=True)
    settings = dict(wavelet=args.wavelet, levels=args.levels, size=args.size, keep=args.keep)
    (args.out / "rate_distortion.json").write_text(json.dumps(dict(settings=settings, rows=rows), indent=1))
    (args.out / "rate_distortion.md").write_text(table(rows))
    plot(rows, volumes, args.figure, log)
    log(f"written: {args.out / 'rate_distortion.json'}, {args.out / 'rate_distortion.md'}, {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
