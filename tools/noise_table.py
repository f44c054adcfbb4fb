"""docs/model.md §2's noise table: a noisy volume's models by ``keep=0.05`` and by ``noise=K`` against its noise-free
truth: the RMS error over the non-empty voxels in units of the noise, and the correlation of the moment-0 map (the
model's voxels summed along axis 0) with the truth's.

    python tools/noise_table.py NOISY.npy CLEAN.npy [--sigma S] [--levels 3]

``--sigma``: the noise's known deviation (default: the one measured, ``measure_noise``).  The table of model.md is the
new-user trial's HI cube (``hi_disk_raw.npy`` and ``hi_clean.npy`` of /work/notes/s21/trial26/make_cubes.py, NaN read
as 0).
"""

import argparse
import warnings

import numpy as np

import clwave


def correlation(a, b) -> float:
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("noisy")
    p.add_argument("clean")
    p.add_argument("--sigma", type=float)
    p.add_argument("--levels", type=int, default=3)
    args = p.parse_args()
    noisy = np.nan_to_num(np.load(args.noisy).astype(np.float32))
    clean = np.nan_to_num(np.load(args.clean).astype(np.float32))
    inside, truth = noisy != 0, clean.sum(0)
    print(f"| {args.levels} levels | keep=0.05 | noise=3 | noise=4 |\n|---|---|---|---|")
    for wavelet in ("haar", "linear", "quadratic", "cubic"):
        wv = clwave.WaveletVolume.from_volume(clwave.Volume(noisy), wavelet, levels=args.levels)
        sigma = args.sigma or wv.measure_noise()[0]
        cells = []
        for rule in (dict(keep=0.05), dict(noise=3), dict(noise=4)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", clwave.ClwaveWarning)  # the cubic's noise gain: the table shows it
                model = wv.threshold(**rule)
            voxels = model.reconstruct().data
            rms = np.sqrt(np.mean((voxels - clean)[inside] ** 2)) / sigma
            kept = 100 * model.kept / model.n_voxels
            cells.append(f"{rms:.2f} σ, r {correlation(voxels.sum(0), truth):.3f} ({kept:.2f} %)")
        print(f"| {wavelet} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
