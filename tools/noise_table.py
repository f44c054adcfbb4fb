"""docs/model.md §2's noise table: a noisy volume's models by ``keep=0.05`` and by ``noise=K`` against its noise-free
truth: the RMS error over the non-empty voxels in units of the noise, and the correlation of the moment-0 map (the
model's voxels summed along axis 0) with the truth's.

    python tools/noise_table.py [NOISY.npy CLEAN.npy] [--sigma S] [--levels 3]

``--sigma``: the noise's known deviation (default: the one measured, ``measure_noise``).  Without files, the table of
model.md: a new-user trial's HI cube (:func:`hi_disk`), NaN outside its beam read as 0.
"""

import argparse
import warnings

import numpy as np

import clwave


def correlation(a, b) -> float:
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def hi_disk(seed=26) -> tuple:
    """(noisy, clean): a thin disk inclined 60° with a flat rotation curve and a bright clump, as a 96-channel HI cube
    of 128² pixels (5 km/s channels, peak 20 mJy/beam), plus noise of σ = 1 mJy/beam, 0 outside a beam of radius 60."""
    ny = nx = 128
    channels = (np.arange(96) - 47.5) * 5e3
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    east, north = -(x - nx / 2 + 0.5), y - ny / 2 + 0.5  # RA increases to the left
    pa, inc = np.radians(30.0), np.radians(60.0)
    major = east * np.sin(pa) + north * np.cos(pa)
    minor = (-east * np.cos(pa) + north * np.sin(pa)) / np.cos(inc)
    r = np.hypot(major, minor) + 1e-6
    speed = 200e3 * (1 - np.exp(-r / 6.0)) * np.sin(inc) * major / r
    surface = (np.exp(-r / 22.0) + 1.5 * np.exp(-((east - 25) ** 2 + (north - 5) ** 2) / 18.0)) * (r < 50)
    clean = (20e-3 * surface * np.exp(-(channels[:, None, None] - speed) ** 2 / 2e8)).astype(np.float32)
    noisy = clean + np.random.default_rng(seed).normal(0, 1e-3, clean.shape).astype(np.float32)
    noisy[:, np.hypot(x - nx / 2 + 0.5, y - ny / 2 + 0.5) > 60] = 0
    return noisy, clean


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("noisy", nargs="?")
    p.add_argument("clean", nargs="?")
    p.add_argument("--sigma", type=float)
    p.add_argument("--levels", type=int, default=3)
    args = p.parse_args()
    if args.noisy is None:
        noisy, clean = hi_disk()
    else:
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
