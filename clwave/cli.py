"""The ``clwave`` command line (never interactive).

Every user mistake ends with one line ``clwave: error: ...`` on stderr and exit
code 2; an existing output file is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from .errors import ClwaveError, InputError, OutputExistsError

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the whole usage first)."""

    def error(self, message):
        raise InputError(f"{message} (see `{self.prog} --help`)")


def _numbers(text, name, counts, kind=float) -> tuple:
    """Comma-separated numbers, e.g. ``--spacing 2,1,1``; ``counts`` lists the lengths allowed."""
    try:
        values = tuple(kind(v) for v in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) not in counts:
        allowed = " or ".join(str(c) for c in counts)
        raise InputError(f"{name} {text!r} must be {allowed} comma-separated numbers")
    return values


def _add_input_options(p):
    p.add_argument("input", help="volume file, DICOM folder, .clw file, or phantom:NAME[:N]")
    g = p.add_argument_group("reading the input")
    g.add_argument("--shape", help=".raw only: Z,Y,X or Z,Y,X,C")
    g.add_argument("--dtype", help=".raw only: numpy dtype, e.g. uint16")
    g.add_argument("--byte-order", choices=["<", ">"], help=".raw only: little (<) or big (>) endian")
    g.add_argument("--spacing", help="voxel spacing DZ,DY,DX (or one number); overrides the file")
    g.add_argument("--series", help="DICOM folder with several series: UID or 0-based index")
    g.add_argument("--subtract", type=float, default=0.0, help="value subtracted so outside is ~0 (air, water)")
    g.add_argument("--hu-to-mu", action="store_true", help="CT: Hounsfield units to attenuation per mm")


def _add_model_options(p, default_tf=None):
    g = p.add_argument_group("wavelet model")
    g.add_argument("--wavelet", default="cubic",
                   help="haar, linear, quadratic or cubic; or one per channel, comma-separated")
    g.add_argument("--levels", type=int, default=3, help="decomposition levels (default 3)")
    k = g.add_mutually_exclusive_group()
    k.add_argument("--keep", type=float, help="fraction of voxels kept as coefficients, (0, 1]")
    k.add_argument("--threshold", type=float, help="keep coefficients above this importance")
    g.add_argument("--focus", help="local level of detail: world centre X,Y,Z (needs --sigma)")
    g.add_argument("--sigma", type=float, help="local level of detail: Gaussian width (world units)")
    g.add_argument("--interpolate", action="store_true", help="interpolating instead of approximating model")
    g.add_argument("--tf", default=default_tf, help="classify with a transfer-function preset first")
    g.add_argument("--tf-window", default=None, help="transfer-function window: auto or LO,HI")


def read_volume(args):
    """The Volume named by ``args.input`` (a file, a folder or ``phantom:NAME[:N]``)."""
    from .io.loaders import load
    from .io.phantoms import phantom
    from .model.volume import Volume

    spec = args.input
    spacing = None if args.spacing is None else _numbers(args.spacing, "--spacing", (1, 3))
    if spec.startswith("phantom:"):
        parts = spec.split(":")
        if len(parts) > 3 or (len(parts) == 3 and not parts[2].isdigit()):
            raise InputError(f"{spec!r}: write phantom:NAME or phantom:NAME:N (N voxels per axis)")
        vol = phantom(parts[1], n=int(parts[2]) if len(parts) == 3 else 128)
        return vol if spacing is None else Volume(vol.data, spacing=spacing)
    shape = None if args.shape is None else _numbers(args.shape, "--shape", (3, 4), int)
    series = args.series
    if series is not None and series.isdigit():
        series = int(series)
    return load(spec, shape=shape, dtype=args.dtype, spacing=spacing, byte_order=args.byte_order,
                series=series, background=args.subtract, hu_to_mu=args.hu_to_mu)


def build_model(args, log=print):
    """Read, classify (``--tf``), decompose and threshold as the options say.

    Returns ``(wavelet_volume, reference_volume)``; the reference is the volume the
    model approximates (None when the input was already a ``.clw`` file).
    """
    from .model.transfer import TransferFunction
    from .model.wavelet import WaveletVolume

    focus = None
    if args.focus is not None or args.sigma is not None:
        if args.focus is None or args.sigma is None:
            raise InputError("--focus X,Y,Z and --sigma S go together")
        focus = (_numbers(args.focus, "--focus", (3,)), args.sigma)
    if args.input.lower().endswith(".clw"):
        wv, reference = WaveletVolume.open(args.input), None
    else:
        vol = read_volume(args)
        tf = None
        if args.tf:
            window = args.tf_window
            if window not in (None, "auto"):
                window = _numbers(window, "--tf-window", (2,))
            tf = TransferFunction.preset(args.tf, window=window).resolved(vol)  # records an "auto" window
            vol = tf.classify(vol)
        wavelet = args.wavelet.split(",") if "," in args.wavelet else args.wavelet
        start = time.perf_counter()
        wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=args.levels,
                                       interpolate=args.interpolate, transfer_function=tf)
        log(f"decomposed {vol.shape} x {vol.channels} channel(s) in {time.perf_counter() - start:.2f} s")
        reference = vol
    if args.keep is not None or args.threshold is not None:
        wv = wv.threshold(keep=args.keep, threshold=args.threshold, focus=focus)
    elif focus is not None:
        raise InputError("--focus selects where detail is kept: give --keep or --threshold too")
    return wv, reference


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
    wv, reference = build_model(args)
    start = time.perf_counter()
    wv.save(out, overwrite=args.force)
    saved = time.perf_counter() - start
    size = out.stat().st_size
    raw = int(np.prod(wv.shape)) * wv.channels * 4
    print(f"shape (z, y, x)       {wv.shape} x {wv.channels} channel(s), spacing {wv.spacing}")
    print(f"wavelet, levels       {', '.join(dict.fromkeys(wv.wavelets))}, {wv.levels}")
    print(f"coefficients kept     {wv.kept:,} of {int(np.prod(wv.shape)):,} voxels")
    print(f"compression           {100 * wv.compression:.2f} %")
    print(f"file size             {size:,} bytes ({100 * size / raw:.2f} % of raw float32), "
          f"written in {saved:.2f} s to {out}")
    if reference is not None:
        rec = wv.reconstruct().data
        error = np.linalg.norm(rec - reference.data) / max(np.linalg.norm(reference.data), 1e-30)
        print(f"relative L2 error     {error:.3e}")
    return 0


def _camera_options(p):
    g = p.add_argument_group("view")
    g.add_argument("--azimuth", type=float, default=30.0, help="degrees (default 30)")
    g.add_argument("--elevation", type=float, default=20.0, help="degrees (default 20)")
    g.add_argument("--size", default="512", help="image size: N or HxW (default 512)")
    g.add_argument("--extent", type=float, help="world width of the image (default: fits every view)")
    g.add_argument("--window", dest="display_window", default="auto", help="PNG window: auto or LO,HI")
    g.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    g.add_argument("--omega-s", type=float, help="footprint band (paper eq. 35; default from the pixel size)")
    g.add_argument("--coarse", type=float, help="splatting: draw coarse cubic bands into coarser framebuffers "
                   "within this error relative to the image maximum (e.g. 1e-2; default: off)")


def _raytrace_options(p):
    g = p.add_argument_group("ray tracing (--method raytrace)")
    g.add_argument("--perspective", action="store_true", help="perspective camera (default orthographic)")
    g.add_argument("--fov", type=float, default=30.0, help="perspective: vertical field of view, degrees")
    g.add_argument("--distance", type=float, help="perspective: eye distance from the target (world units)")
    g.add_argument("--tolerance", type=float, default=1e-3, help="absolute error per output value (1e-3)")
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

    size = _numbers(args.size.replace("x", ","), "--size", (1, 2), int)
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
    wv, _ = build_model(args)
    if args.method == "raytrace":
        tracer = RayTracer(wv, device=args.device, field=args.field)
        options = dict(tolerance=args.tolerance, lights=_lights(args), shading=not args.no_shading,
                       absorption=not args.xray)

        def render(cam):
            return raytrace(wv, cam, tracer=tracer, **options)
    else:
        renderer = SplatRenderer(wv, device=args.device, omega_s=args.omega_s, coarse=args.coarse)

        def render(cam):
            return splat(wv, cam, renderer=renderer)
    if args.turntable is None:
        result = render(camera)
        result.save(out, window=_display_window(args), background=background, overwrite=args.force)
    else:
        results = [render(camera.rotated(360.0 * i / args.turntable)) for i in range(args.turntable)]
        window = _display_window(args)
        if window == "auto" and results[0].is_xray:  # one window for the whole turn: no flicker
            window = resolve_window(np.stack([r.image[..., :3] for r in results]), "auto")
        _write_gif(out, [r.to_uint8(window, background) for r in results], 0.1, args.force)
        result = results[0]
        result.meta["turntable_seconds"] = [_total_seconds(r.meta) for r in results]
    if args.raw:
        result.save(args.raw, overwrite=args.force)
    if args.stats:
        result.save(args.stats, overwrite=args.force)
    size = f"{camera.size[0]}x{camera.size[1]}"
    m = result.meta
    if args.method == "raytrace":
        print(f"ray traced {size} ({m['mode']}, {m['field']} field, tolerance {m['tolerance']:g}, shading "
              f"{m['shading']}) in {m['render_seconds']:.3f} s: {m['segments']:,} segments, "
              f"{m['rays_terminated_early']:,} rays terminated early (set-up {m['setup_seconds']:.2f} s and "
              f"kernel build {m['compile_seconds']:.2f} s apart) -> {out}")
    else:
        s = m["seconds"]
        print(f"splatted {m['coefficients']:,} coefficients at {size} in {s['total']:.3f} s (footprints "
              f"{s['footprints']:.3f}, binning {s['binning']:.3f}, accumulation {s['accumulation']:.3f}; "
              f"kernel build {s['compile']:.2f} s apart) -> {out}")
    return 0


def _total_seconds(meta) -> float:
    return meta["render_seconds"] if meta["method"] == "raytrace" else meta["seconds"]["total"]


def cmd_progressive(args):
    from .splat.progressive import progressive
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
    wv, _ = build_model(args)
    steps = 8 if args.steps is None and args.budget is None else args.steps
    frames = list(progressive(wv, camera, steps=steps, budget=args.budget, device=args.device,
                              omega_s=args.omega_s, coarse=args.coarse))
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
        print(f"frame {f['index']}: {f['coefficients']:>10,} coefficients ({100 * f['fraction']:6.2f} %), "
              f"energy missing {1 - f['energy']:.2e}, {f['seconds']:.3f} s, RMS error {f['rms_error']:.3e}, "
              f"max error {f['max_error']:.3e}")
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
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("info", help="list OpenCL platforms and devices, and the one chosen")
    p.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    p.add_argument("--check", action="store_true", help="also build and run a self-test kernel")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=cmd_info)

    _command(sub, "compress", "write a thresholded wavelet volume (.clw)", cmd_compress, "output .clw file")
    p = _command(sub, "render", "render an image: wavelet splatting (X-ray) or ray tracing (shaded)", cmd_render,
                 "output .png (or .gif with --turntable)", view=True)
    p.add_argument("--method", choices=["splat", "raytrace"], default="splat",
                   help="splat: X-ray line integrals; raytrace: emission-absorption, shaded (needs --tf)")
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


def main(argv=None) -> int:
    try:
        args = make_parser().parse_args(argv)
        return args.run(args)
    except ClwaveError as exc:
        print(f"clwave: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("clwave: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
