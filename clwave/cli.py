"""The ``clwave`` command line (never interactive).

Every user mistake ends with one line ``clwave: error: ...`` on stderr and exit
code 2; an existing output file is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from .errors import ClwaveError, InputError, OutputExistsError
from .memory import check_fits

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the whole usage first)."""

    def error(self, message):
        raise InputError(f"{message} (see `{self.prog} --help`)")


DEFAULT_KEEP = 0.05  # fraction of voxels kept when a volume is compressed without --keep or --threshold
DEFAULT_WAVELET, DEFAULT_LEVELS = "cubic", 3
#: host bytes per float32 value of the volume below which decomposing and thresholding it cannot run: the
#: in-memory model peaks at 3 (RGBA) to 9 (scalar) times the volume; work beyond 4 times what is available
#: is refused before it starts
MODEL_BYTES_PER_VALUE = 16


def _numbers(text, name, counts, kind=float, sep=",") -> tuple:
    """Numbers separated by ``sep``, e.g. ``--spacing 2,1,1``; ``counts`` lists the lengths allowed."""
    try:
        values = tuple(kind(v) for v in str(text).split(sep))
    except ValueError:
        values = ()
    if len(values) not in counts:
        allowed = " or ".join(str(c) for c in counts)
        words = "comma-separated numbers" if sep == "," else f"numbers separated by {sep!r}"
        raise InputError(f"{name} {text!r} must be {allowed} {words}")
    return values


def _add_input_options(p):
    p.add_argument("input", help="volume file, DICOM folder, .clw file, or phantom:NAME[:N]")
    g = p.add_argument_group("reading the input")
    g.add_argument("--shape", help=".raw only: Z,Y,X or Z,Y,X,C")
    g.add_argument("--dtype", help=".raw only: numpy dtype, e.g. uint16")
    g.add_argument("--byte-order", choices=["<", ">"], help=".raw only: little (<) or big (>) endian")
    g.add_argument("--spacing", help="voxel spacing DZ,DY,DX (or one number); overrides the file")
    g.add_argument("--series", help="DICOM folder with several series: UID or 0-based index")
    g.add_argument("--subtract", type=float, help="value subtracted so outside is ~0 (air, water)")
    g.add_argument("--hu-to-mu", action="store_true", help="CT: Hounsfield units to attenuation per mm")
    g.add_argument("--level", type=int, help="OME-Zarr: the multiscale level to read (default 0, the finest)")
    g.add_argument("--chunks", help="read chunk by chunk, never whole (docs/chunked.md): auto, off, or a chunk "
                                    "edge N (default: Zarr and HDF5 always, .npy/.raw/.nii from 1 GiB)")
    c = p.add_argument_group("chunked work (a chunked input; docs/chunked.md)")
    w = c.add_mutually_exclusive_group()
    w.add_argument("--workers", type=int, help="a local Dask cluster of N worker processes (default: threads)")
    w.add_argument("--scheduler", help="address tcp://HOST:PORT of a running Dask scheduler")


def _add_model_options(p):
    from .model.transfer import TransferFunction

    g = p.add_argument_group("wavelet model (from a volume; a .clw input is a model already)")
    g.add_argument("--wavelet", help=f"haar, linear, quadratic or cubic; or one per channel, comma-separated "
                                     f"(default {DEFAULT_WAVELET})")
    g.add_argument("--levels", type=int, help=f"decomposition levels (default {DEFAULT_LEVELS})")
    k = g.add_mutually_exclusive_group()
    k.add_argument("--keep", type=float, help=f"fraction of voxels kept as coefficients, (0, 1] (default "
                                              f"{DEFAULT_KEEP} for a volume; 1 keeps every coefficient)")
    k.add_argument("--threshold", type=float, help="keep coefficients above this importance")
    g.add_argument("--focus", help="local level of detail: world centre X,Y,Z (needs --sigma)")
    g.add_argument("--sigma", type=float, help="local level of detail: Gaussian width (world units)")
    g.add_argument("--interpolate", action="store_true", help="interpolating instead of approximating model")
    g.add_argument("--tf", help="classify with a transfer-function preset first: "
                                + ", ".join(TransferFunction.PRESETS))
    g.add_argument("--tf-window", help="transfer-function window: auto or LO,HI")


def read_volume(args):
    """The Volume named by ``args.input`` (a file, a folder or ``phantom:NAME[:N]``)."""
    from .io.loaders import load
    from .io.phantoms import phantom
    from .model.volume import Volume

    spec = args.input
    spacing = None if args.spacing is None else _numbers(args.spacing, "--spacing", (1, 3))
    if spec.startswith("phantom:"):
        given = [_flag(n) for n in ("shape", "dtype", "byte_order", "series", "hu_to_mu", "level", "chunks")
                 if getattr(args, n, None) is not None and getattr(args, n) is not False]
        if given:
            raise InputError(f"{', '.join(given)} cannot apply to {spec}: a phantom is not read from a file")
        parts = spec.split(":")
        if len(parts) > 3 or (len(parts) == 3 and not parts[2].isdigit()):
            raise InputError(f"{spec!r}: write phantom:NAME or phantom:NAME:N (N voxels per axis)")
        n = int(parts[2]) if len(parts) == 3 else 128
        check_fits(MODEL_BYTES_PER_VALUE * n ** 3 * (4 if args.tf else 1), f"decomposing a {n}^3 phantom",
                   "choose a smaller N")
        vol = phantom(parts[1], n=n)
        return vol if spacing is None else Volume(vol.data, spacing=spacing)
    shape = None if args.shape is None else _numbers(args.shape, "--shape", (3, 4), int)
    series = args.series
    if series is not None and series.isdigit():
        series = int(series)
    return load(spec, shape=shape, dtype=args.dtype, spacing=spacing, byte_order=args.byte_order,
                series=series, level=args.level, chunks=_chunks(args.chunks), background=args.subtract or 0.0,
                hu_to_mu=args.hu_to_mu)


def _chunks(text):
    """``load``'s ``chunks=`` from ``--chunks auto|off|N``."""
    if text is None or text == "auto":
        return text
    if text == "off":
        return False
    if not text.isdigit() or int(text) < 2:
        raise InputError(f"--chunks {text} must be auto, off or a chunk edge N >= 2 (voxels)")
    return int(text)


def _scheduler(args):
    """The Dask scheduler of chunked work: ``--workers N``, ``--scheduler ADDRESS`` or threads (None)."""
    from .cluster import check_scheduler

    return check_scheduler(args.workers if args.workers is not None else args.scheduler)


#: options that make a model from a volume, and so cannot apply to a .clw input (a model already)
VOLUME_ONLY = ("tf", "tf_window", "wavelet", "levels", "interpolate", "spacing", "shape", "dtype", "byte_order",
               "series", "subtract", "hu_to_mu", "level", "chunks", "workers", "scheduler")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _thresholding(args) -> dict:
    """``threshold()`` arguments from ``--keep``, ``--threshold``, ``--focus``/``--sigma``, checked before any work."""
    from .model.wavelet import check_thresholding

    focus = None
    if args.focus is not None or args.sigma is not None:
        if args.focus is None or args.sigma is None:
            raise InputError("--focus X,Y,Z and --sigma S go together")
        if args.keep is None and args.threshold is None and args.input.lower().endswith(".clw"):
            raise InputError("--focus selects where detail is kept: give --keep or --threshold too")
        focus = (_numbers(args.focus, "--focus", (3,)), args.sigma)
    keep, threshold, focus = check_thresholding(args.keep, args.threshold, focus)
    return dict(keep=keep, threshold=threshold, focus=focus)


def _needs_rgba(name, channels, fix) -> InputError:
    return InputError(f"shaded ray tracing needs a classified (RGBA, 4 channels) model, {name} has {channels} "
                      f"channel(s): {fix}, or render line integrals with --xray")


def build_model(args, log=print, rgba=False, gather=True, cluster_render=False):
    """Read, classify (``--tf``), decompose and threshold as the options say; every option is
    checked before the work starts.  ``rgba``: the caller needs 4 channels (shaded ray tracing).

    Returns ``(wavelet_volume, reference_volume)``; the reference is the volume the
    model approximates (None when the input was already a ``.clw`` file).  A chunked input gives no
    reference, and with ``gather`` false a :class:`~clwave.model.chunked.ChunkedWaveletVolume`
    (thresholded, not gathered).  ``cluster_render``: a ``.clw`` input takes ``--workers``/``--scheduler``
    (the render runs there).
    """
    from .model.transfer import TransferFunction
    from .model.wavelet import WaveletVolume, check_decomposition

    thresholding = _thresholding(args)
    scheduler = _scheduler(args)
    if args.input.lower().endswith(".clw"):
        given = [_flag(name) for name in VOLUME_ONLY if getattr(args, name, None) not in (None, False)
                 and not (cluster_render and name in ("workers", "scheduler"))]
        if given:
            raise InputError(f"{', '.join(given)} cannot apply to {args.input}: a .clw file is a wavelet model "
                             f"already; compress the original volume with {'them' if len(given) > 1 else 'it'}")
        wv = WaveletVolume.open(args.input, keep=args.keep if args.focus is None else None)
        if rgba and wv.channels != 4:
            raise _needs_rgba(args.input, wv.channels, "compress the volume with --tf PRESET")
        if args.threshold is not None or args.focus is not None:  # --keep alone: a prefix of the file
            wv = wv.threshold(**thresholding)
        return wv, None
    vol = read_volume(args)
    tf = None
    if args.tf:
        window = args.tf_window
        if window not in (None, "auto"):
            window = _numbers(window, "--tf-window", (2,))
        tf = TransferFunction.preset(args.tf, window=window)
    elif args.tf_window is not None:
        raise InputError("--tf-window sets the window of a --tf preset: give --tf too")
    if rgba and tf is None and vol.channels != 4:
        presets = ", ".join(TransferFunction.PRESETS)
        raise _needs_rgba(args.input, vol.channels, f"classify it with --tf PRESET ({presets})")
    wavelet = args.wavelet or DEFAULT_WAVELET
    wavelet = wavelet.split(",") if "," in wavelet else wavelet
    wavelet, levels = check_decomposition(vol.shape, 4 if tf else vol.channels, wavelet,
                                          DEFAULT_LEVELS if args.levels is None else args.levels)
    if not vol.chunked:
        check_fits(MODEL_BYTES_PER_VALUE * int(np.prod(vol.shape)) * (4 if tf else vol.channels),
                   "decomposing this volume", "read it chunk by chunk (--chunks auto), or crop or subsample it")
    elif args.interpolate:
        raise InputError("--interpolate needs the whole volume in memory (its prefilter is global); leave it out "
                         "for a chunked input, or read the input whole with --chunks off")
    if tf is not None:
        tf = tf.resolved(vol)  # records an "auto" window
        vol = tf.classify(vol)
    start = time.perf_counter()
    wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels, interpolate=args.interpolate,
                                   transfer_function=tf, scheduler=scheduler)
    log(f"{'read (content) of' if vol.chunked else 'decomposed'} {' x '.join(map(str, vol.shape[::-1]))} voxels "
        f"(x, y, z), {vol.channels} channel(s), in {time.perf_counter() - start:.2f} s")
    if args.keep is None and args.threshold is None:
        thresholding["keep"] = DEFAULT_KEEP
    wv = wv.threshold(**thresholding)
    if not vol.chunked:
        return wv, vol
    return (wv.compute() if gather else wv), None


def _check_output(path, force):
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; pass --force to replace it")
    if not path.parent.exists():
        raise InputError(f"the folder of {path} does not exist; create it first")
    return path


# ------------------------------------------------------------------ commands


def cmd_info(args):
    from .device.context import list_devices, requested_device, select_device
    from .device.programs import selftest

    devices = list_devices()
    chosen = select_device(args.device, devices)
    if args.json:
        print(json.dumps(dict(devices=[d.describe() for d in devices], auto=chosen.id,
                              request=requested_device(args.device)), indent=2))
    else:
        mib = 1024 ** 2
        platform = None
        for d in devices:
            if d.platform != platform:
                platform = d.platform
                print(f"platform {d.platform_index}: {d.platform}")
            mark = "  <- chosen" if d == chosen else ""
            print(f"  {d.id}  {d.name} [{d.kind}]{mark}\n"
                  f"        global memory {d.global_mem / mib:,.0f} MiB, max allocation "
                  f"{d.max_alloc / mib:,.0f} MiB, local memory {d.local_mem / 1024:,.0f} KiB, "
                  f"{d.compute_units} compute units, {d.version}")
        print(f"device request {requested_device(args.device)!r} -> {chosen.id} {chosen.name}")
    if args.check:
        from .device.context import ComputeContext
        seconds = selftest(ComputeContext.get(chosen.id))
        print(f"self-test kernel built in {seconds:.2f} s and ran correctly on {chosen.name}")
    return 0


def cmd_compress(args):
    out = _check_output(args.output, args.force)
    if out.suffix.lower() != ".clw":
        raise InputError(f"output {out} must end in .clw")
    from .io.clw import check_quantise, read_clw

    quantise = args.quantise
    if quantise not in (None, "auto"):
        try:
            quantise = float(quantise)
        except ValueError:
            pass  # check_quantise names it
    quantise = check_quantise(quantise)  # before any work
    wv, reference = build_model(args, gather=False)
    start = time.perf_counter()
    wv.save(out, overwrite=args.force, quantise=quantise)
    saved = time.perf_counter() - start
    size, voxels = out.stat().st_size, wv.n_voxels
    raw = voxels * wv.channels * 4  # the volume the model approximates, as float32
    classified = f", classified to {wv.channels} channels (--tf {args.tf})" if args.tf else ""
    print(f"input                 {args.input}: {' x '.join(map(str, wv.shape[::-1]))} voxels (x, y, z)"
          f"{classified}{_on_disk(args.input)}")
    print(f"model                 {', '.join(dict.fromkeys(wv.wavelets))} wavelets, {wv.levels} levels, "
          f"{wv.kept:,} coefficients = {100 * wv.kept / voxels:.2f} % of the voxels")
    print(f"file                  {out}: {_bytes(size)}, {raw / size:.1f}:1 against the volume as raw float32 "
          f"({_bytes(raw)}), written in {saved:.2f} s")
    if reference is not None:
        stored = wv if quantise is None else read_clw(out)  # the rounded values, as the file holds them
        error = np.sqrt(np.mean((stored.reconstruct().data - reference.data) ** 2))
        peak = max(float(np.max(np.abs(reference.data))), np.finfo(np.float32).tiny)
        print(f"error                 RMS over the voxels {error / peak:.2e} of the largest value "
              f"(PSNR {20 * np.log10(peak / max(error, 1e-30)):.1f} dB)")
    elif not args.input.lower().endswith(".clw"):
        print("error                 not measured: the input was read chunk by chunk (the error needs it whole)")
    return 0


def _on_disk(spec) -> str:
    """", N MB on disk" for an input file or folder (nothing for a phantom)."""
    path = Path(spec)
    if spec.startswith("phantom:") or not path.exists():
        return ""
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    return f", {_bytes(sum(p.stat().st_size for p in files))} on disk"


def _bytes(n) -> str:
    for unit in ("bytes", "KB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:,.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000


def _camera_options(p):
    g = p.add_argument_group("view")
    g.add_argument("--azimuth", type=float, default=30.0, help="degrees (default 30)")
    g.add_argument("--elevation", type=float, default=20.0, help="degrees (default 20)")
    g.add_argument("--size", default="512", help="image size: N or HxW, e.g. 512 or 300x400 (default 512)")
    g.add_argument("--extent", type=float, help="world width of the image (default: the bounding sphere of the "
                                                 "non-empty voxels spans the image, the same at every view)")
    g.add_argument("--window", dest="display_window", default="auto", help="PNG window: auto or LO,HI")
    g.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    g.add_argument("--omega-s", type=float, help="footprint band (paper eq. 35; default from the pixel size)")
    g.add_argument("--coarse", type=float, help="splatting: draw coarse cubic bands into coarser framebuffers "
                   "within this error relative to the image maximum (e.g. 1e-2; default: off)")
    g.add_argument("--device-memory", metavar="SIZE", help="device memory to use at most, e.g. 2GiB or 512M "
                   "(default: the device's); splatting streams coefficients beyond it in chunks (docs/splatting.md "
                   "§6), ray tracing renders bricks beyond it in passes (docs/raytracing.md §6)")


def _raytrace_options(p):
    g = p.add_argument_group("ray tracing (--method raytrace)")
    g.add_argument("--perspective", action="store_true", help="perspective camera (default orthographic)")
    g.add_argument("--fov", type=float, default=30.0, help="perspective: vertical field of view, degrees")
    g.add_argument("--distance", type=float, help="perspective: eye distance from the target (world units)")
    g.add_argument("--tolerance", type=float, default=1e-3, help="absolute error per output value (default 1e-3)")
    g.add_argument("--light", action="append", help="directional light AZ,EL in degrees; repeat for more; "
                   "'none' for ambient only (default: a headlight)")
    g.add_argument("--no-shading", action="store_true", help="unlit emission")
    g.add_argument("--xray", action="store_true", help="line integrals without absorption, as splatting")
    g.add_argument("--background", default="0,0,0", help="PNG: colour R,G,B in 0..1 behind the volume")
    g.add_argument("--field", choices=("bspline", "wavelet"), default="bspline",
                   help="evaluate the field from fine B-spline grids (fast) or from the wavelet coefficients "
                        "with per-ray active lists (the paper's reference)")


def make_camera(args):
    from .model.camera import Camera

    size = _numbers(args.size.lower(), "--size", (1, 2), int, sep="x")
    perspective = dict(perspective=True, distance=args.distance, fov=args.fov) \
        if getattr(args, "perspective", False) else {}
    return Camera(args.azimuth, args.elevation, size if len(size) == 2 else size[0], extent=args.extent,
                  **perspective)


def _lights(args):
    if args.light is None:
        return None
    if args.light == ["none"]:
        return []
    return [tuple(_numbers(spec, "--light", (2,))) for spec in args.light]


def _display_window(args):
    return "auto" if args.display_window == "auto" else _numbers(args.display_window, "--window", (2,))


def _device_memory(args):
    """``device_memory=`` from ``--device-memory SIZE``, checked before any work."""
    from .device.memory import parse_cap

    return parse_cap(args.device_memory)


def _write_gif(path, pictures, seconds_per_frame, force):
    import imageio.v3 as iio

    from .io.files import write_atomic
    write_atomic(path, lambda fh: iio.imwrite(fh, np.stack(pictures), extension=".gif",
                                              is_batch=True, duration=int(1000 * seconds_per_frame), loop=0),
                 force)


def cmd_render(args):
    from .raytrace.tracer import RayTracer, raytrace
    from .io.result import resolve_window
    from .splat.renderer import SplatRenderer, splat
    from .cluster import check_model_file, client_for as cluster_client

    out = _check_output(args.output, args.force)
    extras = [Path(p) for p in (args.raw, args.stats) if p]
    for extra in extras:
        _check_output(extra, args.force)
    if args.turntable is not None and (args.turntable < 1 or out.suffix.lower() != ".gif"):
        raise InputError("--turntable N needs N >= 1 and an output ending in .gif")
    if args.turntable is None and out.suffix.lower() != ".png":
        raise InputError(f"output {out} must end in .png (or .gif with --turntable N)")
    background = _numbers(args.background, "--background", (3,))
    camera = make_camera(args)
    if args.method == "splat" and camera.perspective:
        raise InputError("--perspective is for --method raytrace; splatting renders orthographic views")
    if args.method == "raytrace" and args.coarse is not None:
        raise InputError("--coarse is for --method splat; ray tracing controls its error with --tolerance")
    device_memory = _device_memory(args)
    if args.omega_s is not None and not (np.isfinite(args.omega_s) and args.omega_s > 0):
        raise InputError(f"--omega-s {args.omega_s:g} must be a positive band, e.g. 14")
    if not (np.isfinite(args.tolerance) and args.tolerance > 0):
        raise InputError(f"--tolerance {args.tolerance:g} must be a positive absolute error, e.g. 1e-3")
    lights, window = _lights(args), _display_window(args)
    on_cluster = args.input.lower().endswith(".clw") and (args.workers, args.scheduler) != (None, None)
    wv, _ = build_model(args, rgba=args.method == "raytrace" and not args.xray, cluster_render=on_cluster)
    if on_cluster:  # docs/raytracing.md §7, docs/splatting.md §7: each worker opens the file
        from .raytrace.regions import check_cluster_model

        if args.method == "raytrace":
            check_cluster_model(wv, args.field)
        else:
            check_model_file(wv, "splatting")
    cluster = cluster_client(_scheduler(args)) if on_cluster else contextlib.nullcontext()
    if args.method == "raytrace":
        options = dict(tolerance=args.tolerance, lights=lights, shading=not args.no_shading,
                       absorption=not args.xray)
        if on_cluster:
            options.update(device=args.device, field=args.field, device_memory=device_memory)
        else:
            options["tracer"] = RayTracer(wv, device=args.device, field=args.field, device_memory=device_memory)

        def render(cam):
            return raytrace(wv, cam, scheduler=client, **options)
    else:
        options = dict(device=args.device, omega_s=args.omega_s, coarse=args.coarse, device_memory=device_memory)
        if not on_cluster:
            options = dict(renderer=SplatRenderer(wv, **options))

        def render(cam):
            return splat(wv, cam, scheduler=client, **options)
    cameras = [camera] if args.turntable is None else \
        [camera.rotated(360.0 * i / args.turntable) for i in range(args.turntable)]
    with cluster as client:
        results = [render(cam) for cam in cameras]
    if args.turntable is None:
        result = results[0]
        result.save(out, window=window, background=background, overwrite=args.force)
    else:
        if window == "auto" and results[0].is_xray:  # one window for the whole turn: no flicker
            window = resolve_window(np.stack([r.image[..., :3] for r in results]), "auto")
        _write_gif(out, [r.to_uint8(window, background) for r in results], 0.1, args.force)
        result = results[0]
        result.meta["turntable_seconds"] = [_total_seconds(r.meta) for r in results]
        seconds = result.meta["turntable_seconds"]
        print(f"turntable of {len(results)} views at {camera.size[0]}x{camera.size[1]} in {sum(seconds):.3f} s "
              f"({np.median(seconds):.3f} s a view, median); the first view:")
    if args.raw:
        result.save(args.raw, overwrite=args.force)
    if args.stats:
        result.save(args.stats, overwrite=args.force)
    size = f"{camera.size[0]}x{camera.size[1]}"
    m = result.meta
    if args.method == "raytrace":
        where = f"on {m['workers']} workers in {len(m['slabs'])} slabs" if "slabs" in m else \
            f"{m['rays_terminated_early']:,} rays terminated early"
        print(f"ray traced {size} ({m['mode']}, {m['field']} field, tolerance {m['tolerance']:g}, shading "
              f"{m['shading']}) in {m['render_seconds']:.3f} s: {m['segments']:,} segments, {where} (set-up "
              f"{m['setup_seconds']:.2f} s and kernel build {m['compile_seconds']:.2f} s apart) -> {out}")
    else:
        s = m["seconds"]
        print(f"splatted {m['coefficients']:,} coefficients at {size} in {s['total']:.3f} s (footprints "
              f"{s['footprints']:.3f}, binning {s['binning']:.3f}, accumulation {s['accumulation']:.3f}; "
              f"kernel build {s['compile']:.2f} s apart) -> {out}")
    return 0


def _total_seconds(meta) -> float:
    return meta["render_seconds"] if meta["method"] == "raytrace" else meta["seconds"]["total"]


def cmd_progressive(args):
    from .splat.progressive import check_schedule, progressive
    from .io.result import RenderResult, resolve_window

    out = Path(args.output)
    as_folder = out.suffix == ""
    if not as_folder and out.suffix.lower() != ".gif":
        raise InputError(f"output {out} must end in .gif, or be a folder name for PNG frames")
    if as_folder:
        if out.exists() and any(out.iterdir()) and not args.force:
            raise InputError(f"folder {out} is not empty; pass --force to write into it")
    else:
        _check_output(out, args.force)
    if args.stats:
        _check_output(args.stats, args.force)
    camera = make_camera(args)
    steps = 8 if args.steps is None and args.budget is None else args.steps
    check_schedule(steps, args.budget)
    device_memory = _device_memory(args)
    wv, _ = build_model(args)
    frames = list(progressive(wv, camera, steps=steps, budget=args.budget, device=args.device,
                              omega_s=args.omega_s, coarse=args.coarse, device_memory=device_memory))
    window = _display_window(args)
    if window == "auto":  # the final image's window for every frame: refinement stays visible
        window = resolve_window(frames[0].final_image()[..., :3], "auto")
    pictures = [RenderResult(f.image, f.meta).to_uint8(window) for f in frames]
    if as_folder:
        out.mkdir(parents=True, exist_ok=True)
        for f, picture in zip(frames, pictures):
            RenderResult(f.image, f.meta).save(out / f"frame_{f.index:03d}.png", window=window, overwrite=True)
    else:
        _write_gif(out, pictures, 0.5, args.force)
    figures = [f.figures() for f in frames]
    if args.stats:
        from .io.files import write_atomic
        text = json.dumps(dict(frames=figures, meta=frames[-1].meta), indent=2, default=str).encode()
        write_atomic(args.stats, lambda fh: fh.write(text), args.force)
    for f in figures:
        print(f"frame {f['index']}: {f['coefficients']:>10,} coefficients ({100 * f['fraction']:6.2f} % of those kept, "
              f"{100 * f['voxel_fraction']:.3f} % of the voxels) at {f['seconds']:.3f} s; error against the final "
              f"image: RMS {f['relative_rms_error']:.2e}, max {f['relative_max_error']:.2e} of its largest value")
    return 0


def _command(sub, name, help, run, output_help, view=False):
    """A subcommand reading a volume into a wavelet model and writing ``-o`` (``--force`` to replace)."""
    p = sub.add_parser(name, help=help)
    _add_input_options(p)
    _add_model_options(p)
    if view:
        _camera_options(p)
    p.add_argument("-o", "--output", required=True, help=output_help)
    p.add_argument("--force", action="store_true", help="replace existing output files")
    p.set_defaults(run=run)
    return p


def make_parser():
    parser = _Parser(prog="clwave", description="Wavelet-domain volume rendering (OpenCL).")
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("info", help="list OpenCL platforms and devices, and the one chosen")
    p.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    p.add_argument("--check", action="store_true", help="also build and run a self-test kernel")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=cmd_info)

    p = _command(sub, "compress", "write a thresholded wavelet volume (.clw)", cmd_compress, "output .clw file")
    p.add_argument("--quantise", help="store the values rounded so that no voxel moves by more than this bound "
                                      "(volume units), or 'auto' (half the smallest kept detail); docs/codecs.md")
    p = _command(sub, "render", "render an image: wavelet splatting (X-ray) or ray tracing (shaded)", cmd_render,
                 "output .png (or .gif with --turntable)", view=True)
    p.add_argument("--method", choices=["splat", "raytrace"], default="splat",
                   help="splat (default): X-ray line integrals; raytrace: emission-absorption, shaded (needs a "
                        "classified model: --tf, or a .clw compressed with it; or --xray)")
    _raytrace_options(p)
    p.add_argument("--turntable", type=int, help="write an N-frame rotation GIF")
    p.add_argument("--raw", help="also write the float32 image as .npy")
    p.add_argument("--stats", help="also write the figures as .json")
    p = _command(sub, "progressive", "progressive splatting frames as a GIF or a folder of PNGs", cmd_progressive,
                 "output .gif, or a folder for PNG frames", view=True)
    k = p.add_mutually_exclusive_group()
    k.add_argument("--steps", type=int, help="number of frames (default 8)")
    k.add_argument("--budget", type=float, help="seconds: stop when the next step would not fit")
    p.add_argument("--stats", help="per-frame figures as .json")
    return parser


def _version():
    from . import __version__
    return f"clwave {__version__}"


class Terminated(Exception):
    """SIGTERM, raised where the program is, so that what it was writing is cleaned up on the way out."""


def _terminate(signum, frame):
    raise Terminated()


def main(argv=None) -> int:
    previous = signal.signal(signal.SIGTERM, _terminate) if threading.current_thread() is threading.main_thread() \
        else None
    debug = "--debug" in (sys.argv[1:] if argv is None else argv)
    try:
        args = make_parser().parse_args(argv)
        return args.run(args)
    except ClwaveError as exc:
        print(f"clwave: error: {exc.cli_message()}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("clwave: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("clwave: terminated", file=sys.stderr)
        return 143
    except MemoryError as exc:
        print(f"clwave: error: not enough memory for this work ({exc or 'an allocation failed'}); render fewer "
              f"pixels, keep fewer coefficients or use a smaller volume", file=sys.stderr)
        return EXIT_USAGE
    except Exception as exc:  # a bug: one line, the traceback only when asked for
        if debug:
            raise
        print(f"clwave: internal error ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); "
              f"this is a bug in clwave: please report it with the command line, and run with --debug for the "
              f"traceback", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
