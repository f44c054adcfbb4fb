"""Regression guard for refactors: the same inputs must give the same images, bit for bit.

Renders a fixed set of small, deterministic cases (analytic phantoms, fixed keep fractions,
fixed cameras) through clwave's *public* API only -- ``import clwave`` and the names it
re-exports -- so the script keeps working while internal modules move.  ``save`` writes each
image as ``DIR/<case>.npy`` plus ``DIR/manifest.json`` (case parameters, shape, dtype, SHA-256
of the raw bytes, a few deterministic meta fields, the device); ``compare`` renders again and
checks every image against the saved one bit for bit.  Images are only comparable on the same
OpenCL device and driver (PoCL on the CPU here): a different device may round differently.

    python tools/check_images.py save DIR [--force] [--only CASE ...]
    python tools/check_images.py compare DIR [--only CASE ...]

``compare`` prints one row per case (case, shape, identical, max |diff|, max |diff| / max |saved|)
and exits 1 if any image differs (or is missing), 0 if every one is identical.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import clwave  # noqa: E402

# --------------------------------------------------------------------------- cases
# Every case is plain data (it goes into the manifest as is):
#   volume: phantom name and size, optional transfer-function preset (RGBA classification),
#           wavelet, levels, keep fraction
#   camera: keyword arguments of clwave.Camera (or "cameras": several views, images stacked)
#   method: "splat", "raytrace" or "progressive", with its keyword arguments in "options"
#   api:    "function" (default) or "renderer" (see render())
SCALAR64 = dict(phantom="hydrogen", n=64, wavelet="cubic", levels=3, keep=0.05)
RGBA64 = dict(phantom="hydrogen", n=64, tf="hydrogen", wavelet="cubic", levels=3, keep=0.05)
RGBA48 = dict(phantom="hydrogen", n=48, tf="hydrogen", wavelet="cubic", levels=3, keep=0.05)
OBLIQUE = dict(azimuth=30.0, elevation=20.0, size=128)
AXIS = dict(azimuth=90.0, elevation=0.0, size=128)  # image axes are world axes: Haar "cells" path

CASES = {
    # --- wavelet splatting (X-ray line integrals)
    "splat_scalar_axis": dict(method="splat", volume=SCALAR64, camera=dict(azimuth=0.0, elevation=0.0, size=128)),
    "splat_scalar_oblique": dict(method="splat", volume=SCALAR64, camera=OBLIQUE),
    "splat_scalar_oblique_coarse": dict(method="splat", volume=SCALAR64, camera=OBLIQUE,
                                        options=dict(coarse=2e-2)),  # same view as splat_scalar_oblique
    "splat_rgba_hydrogen_oblique": dict(method="splat", volume=RGBA64, camera=dict(azimuth=-40.0, elevation=25.0,
                                                                                  size=(112, 128))),
    "splat_haar_axis": dict(method="splat", volume=dict(phantom="shepp-logan", n=64, wavelet="haar", levels=3,
                                                        keep=0.05), camera=AXIS),
    "splat_haar_oblique": dict(method="splat", volume=dict(phantom="shepp-logan", n=64, wavelet="haar", levels=3,
                                                           keep=0.05), camera=dict(azimuth=35.0, elevation=15.0,
                                                                                   size=128)),
    "splat_linear_axis": dict(method="splat", volume=dict(phantom="marschner-lobb", n=64, wavelet="linear", levels=3,
                                                          keep=0.05), camera=AXIS),
    "splat_linear_oblique": dict(method="splat", volume=dict(phantom="marschner-lobb", n=64, wavelet="linear",
                                                             levels=3, keep=0.05),
                                 camera=dict(azimuth=-25.0, elevation=40.0, size=128)),
    "splat_renderer_two_views": dict(method="splat", api="renderer", volume=SCALAR64, options=dict(coarse=2e-2),
                                     cameras=[dict(azimuth=10.0, elevation=5.0, size=96),
                                              dict(azimuth=200.0, elevation=-30.0, size=96)]),
    # --- ray tracing in wavelet space
    "raytrace_rgba_shaded_oblique": dict(method="raytrace", api="renderer", volume=RGBA48,
                                         camera=dict(azimuth=30.0, elevation=20.0, size=96),
                                         options=dict(tolerance=1e-2)),
    "raytrace_xray_scalar": dict(method="raytrace", volume=dict(phantom="hydrogen", n=48, wavelet="cubic", levels=3,
                                                                keep=0.05),
                                 camera=dict(azimuth=50.0, elevation=10.0, size=96),
                                 options=dict(tolerance=1e-2, absorption=False)),
    "raytrace_perspective_phong": dict(method="raytrace", api="renderer", volume=RGBA48,
                                       camera=dict(azimuth=-60.0, elevation=35.0, size=96, perspective=True,
                                                   fov=30.0, distance=120.0),
                                       options=dict(tolerance=1e-2, lights=[[30.0, 40.0], [200.0, 0.0]],
                                                    shading=dict(ambient=0.3, diffuse=0.7, specular=0.3,
                                                                 shininess=20.0))),
    "raytrace_wavelet_path_crop": dict(method="raytrace", volume=dict(phantom="hydrogen", n=32, tf="hydrogen",
                                                                      wavelet="cubic", levels=3, keep=0.05),
                                       camera=dict(azimuth=30.0, elevation=20.0, size=24, extent=16.0),
                                       options=dict(tolerance=1e-2, field="wavelet")),
    # --- progressive refinement (frames' images concatenated along a new first axis)
    "progressive_scalar_4_frames": dict(method="progressive", volume=SCALAR64,
                                        camera=dict(azimuth=45.0, elevation=30.0, size=96),
                                        options=dict(steps=4)),
    "progressive_coarse_3_frames": dict(method="progressive", volume=RGBA64,
                                        camera=dict(azimuth=120.0, elevation=-15.0, size=96),
                                        options=dict(steps=3, coarse=2e-2)),
}

#: meta fields that are deterministic (no timings) and worth recording next to each image
META_KEYS = ("method", "field", "texture_sampling", "framebuffers", "coefficients", "shading", "mode", "segments")

_wavelet_volumes: dict = {}
_tracers: dict = {}


def wavelet_volume(spec: dict):
    """The thresholded wavelet volume of a case (cached: several cases share one)."""
    key = json.dumps(spec, sort_keys=True)
    if key not in _wavelet_volumes:
        vol = clwave.phantom(spec["phantom"], n=spec["n"])
        if spec.get("tf"):
            vol = clwave.TransferFunction.preset(spec["tf"]).classify(vol)
        wv = clwave.WaveletVolume.from_volume(vol, wavelet=spec["wavelet"], levels=spec["levels"])
        _wavelet_volumes[key] = wv.threshold(keep=spec["keep"])
    return _wavelet_volumes[key]


def camera(spec: dict) -> clwave.Camera:
    kw = dict(spec)
    if isinstance(kw.get("size"), list):
        kw["size"] = tuple(kw["size"])
    return clwave.Camera(kw.pop("azimuth"), kw.pop("elevation"), **kw)


def render(case: dict):
    """(image, meta) of one case.

    ``api`` picks the entry point: "function" (clwave.splat / clwave.raytrace / clwave.progressive,
    a fresh renderer each time) or "renderer" (one clwave.SplatRenderer / clwave.RayTracer per
    volume, reused across cases and views; with ``cameras`` the views' images are stacked).
    """
    wv, opts = wavelet_volume(case["volume"]), dict(case.get("options", {}))
    api = case.get("api", "function")
    if case["method"] == "splat":
        if api == "renderer":
            r = clwave.SplatRenderer(wv, **opts)  # its buffers are reused from view to view
            results = [clwave.splat(wv, camera(c), renderer=r) for c in case["cameras"]]
            return np.stack([res.image for res in results]), results[-1].meta
        res = clwave.splat(wv, camera(case["camera"]), **opts)
        return res.image, res.meta
    if case["method"] == "raytrace":
        if isinstance(opts.get("shading"), dict):
            opts["shading"] = clwave.Phong(**opts["shading"])
        if opts.get("lights") is not None:
            opts["lights"] = [tuple(light) for light in opts["lights"]]
        if api == "renderer":
            field = opts.pop("field", "bspline")
            key = (json.dumps(case["volume"], sort_keys=True), field)
            if key not in _tracers:  # one tracer per volume and field, shared by the cases that name it
                _tracers[key] = clwave.RayTracer(wv, field=field)
            res = _tracers[key].render(camera(case["camera"]), **opts)
        else:
            res = clwave.raytrace(wv, camera(case["camera"]), **opts)
        return res.image, res.meta
    if case["method"] == "progressive":
        frames = list(clwave.progressive(wv, camera(case["camera"]), **opts))
        meta = dict(frames[-1].meta, frames=[f.coefficients for f in frames])
        return np.stack([f.image for f in frames]), meta
    raise ValueError(f"unknown method {case['method']!r}")


def sha256(image: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()


def picked_meta(meta: dict) -> dict:
    out = {k: meta[k] for k in META_KEYS if k in meta}
    if "frames" in meta:
        out["frames"] = meta["frames"]
    return json.loads(json.dumps(out, default=str))


def git_state() -> dict:
    """Commit and dirtiness of the checkout clwave was imported from (best effort)."""
    root = Path(clwave.__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        return {}
    return dict(git_head=head or None, git_dirty=dirty if head else None)


def environment(device) -> dict:
    return dict(clwave_file=clwave.__file__, clwave_version=clwave.__version__, **git_state(),
                device=json.loads(json.dumps(device, default=str)), python=platform.python_version(),
                numpy=np.__version__, machine=platform.machine())


def run_cases(names):
    """Yield (name, image, meta, seconds) for each case, in order."""
    for name in names:
        start = time.perf_counter()
        image, meta = render(CASES[name])
        yield name, np.ascontiguousarray(image), meta, time.perf_counter() - start


# --------------------------------------------------------------------------- commands
def cmd_save(folder: Path, names, force: bool) -> int:
    manifest_path = folder / "manifest.json"
    if manifest_path.exists() and not force:
        print(f"{manifest_path} exists; pass --force to overwrite", file=sys.stderr)
        return 2
    folder.mkdir(parents=True, exist_ok=True)
    start, cases, device = time.perf_counter(), {}, None
    for name, image, meta, seconds in run_cases(names):
        np.save(folder / f"{name}.npy", image)
        device = device or meta.get("device")
        cases[name] = dict(params=CASES[name], shape=list(image.shape), dtype=str(image.dtype),
                           sha256=sha256(image), max_abs=float(np.max(np.abs(image))) if image.size else 0.0,
                           meta=picked_meta(meta))
        print(f"{name:32s} {str(image.shape):18s} {seconds:6.2f} s  {cases[name]['sha256'][:16]}", flush=True)
    total = time.perf_counter() - start
    manifest = dict(created=time.strftime("%Y-%m-%d %H:%M:%S"), environment=environment(device),
                    seconds=round(total, 2), cases=cases)
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"saved {len(cases)} case(s) to {folder} in {total:.1f} s")
    return 0


def cmd_compare(folder: Path, names, every_case: bool) -> int:
    manifest = json.loads((folder / "manifest.json").read_text())
    saved = manifest["cases"]
    start, rows, notes, device = time.perf_counter(), [], [], None
    for name, image, meta, _ in run_cases(names):
        device = device or meta.get("device")
        ref = saved.get(name)
        path = folder / f"{name}.npy"
        if ref is None or not path.exists():
            rows.append((name, str(image.shape), "no (not in baseline)", "-", "-"))
            continue
        if ref["params"] != json.loads(json.dumps(CASES[name])):
            notes.append(f"{name}: case parameters differ from the baseline's")
        base = np.load(path)
        if sha256(base) != ref["sha256"]:
            notes.append(f"{name}: {path} does not match its manifest hash (file changed?)")
        if base.shape != image.shape or base.dtype != image.dtype:
            rows.append((name, f"{image.shape} vs {base.shape}", f"no ({image.dtype} vs {base.dtype})", "-", "-"))
            continue
        identical = sha256(image) == ref["sha256"] and np.array_equal(image, base, equal_nan=True)
        diff = np.abs(image.astype(np.float64) - base.astype(np.float64))
        max_diff = float(np.nanmax(diff)) if diff.size else 0.0
        scale = float(np.max(np.abs(base))) if base.size else 0.0
        rel = max_diff / scale if scale > 0 else (0.0 if max_diff == 0 else float("inf"))
        rows.append((name, str(image.shape), "yes" if identical else "NO", f"{max_diff:.3e}", f"{rel:.3e}"))
        new_meta = picked_meta(meta)
        if new_meta != ref.get("meta"):
            notes.append(f"{name}: meta differs: saved {ref.get('meta')} now {new_meta}")
    for name in sorted(set(saved) - set(names)) if every_case else ():
        rows.append((name, str(tuple(saved[name]["shape"])), "no (case removed)", "-", "-"))
    saved_device = manifest.get("environment", {}).get("device")
    device = json.loads(json.dumps(device, default=str))
    if saved_device != device:
        notes.append(f"device differs: baseline {saved_device!r}, now {device!r}")

    header = ("case", "shape", "identical", "max abs diff", "max rel diff")
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(5)]
    line = lambda r: "  ".join(str(c).ljust(w) for c, w in zip(r, widths))  # noqa: E731
    print(line(header))
    print(line(["-" * w for w in widths]))
    for r in rows:
        print(line(r))
    for note in notes:
        print("note:", note)
    bad = [r[0] for r in rows if r[2] != "yes"]
    total = time.perf_counter() - start
    print(f"{len(rows) - len(bad)} of {len(rows)} identical ({total:.1f} s); "
          + ("all identical" if not bad else "DIFFERENT: " + ", ".join(bad)))
    return 1 if bad else 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=("save", "compare"))
    p.add_argument("folder", type=Path)
    p.add_argument("--force", action="store_true", help="save: overwrite an existing manifest")
    p.add_argument("--only", nargs="+", metavar="CASE", choices=sorted(CASES), help="these cases only")
    args = p.parse_args(argv)
    names = args.only or list(CASES)
    if args.command == "save":
        return cmd_save(args.folder, names, args.force)
    return cmd_compare(args.folder, names, every_case=not args.only)


if __name__ == "__main__":
    sys.exit(main())
