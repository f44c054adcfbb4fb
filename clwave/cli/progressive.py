"""``clwave progressive``: progressive frames (splatting, or ray tracing) as a GIF or a folder of PNGs."""

from __future__ import annotations

import json

from ..errors import InputError
from ..io.images import write_gif
from ..io.progress import progress
from .checks import check_picture_fits, make_camera, opened, parse_clip, parse_lights, picture_options
from .options import (add_command, add_raytrace_options, build_model, check_frames_output, check_outputs, finish,
                      parse_device_memory, post_transfer_function)


def run(args):
    from ..frames import check_error
    from ..io.files import published_together, write_atomic
    from ..progressive import progressive
    from ..splat.progressive import check_schedule
    from ..io.result import resolve_window

    out = check_frames_output(args.output, args.force)
    as_folder = out.suffix == ""
    check_outputs(args.force, (None if as_folder else out, "-o", (".gif",)), (args.stats, "--stats", (".json",)))
    look = picture_options(args, out / "frame.png" if as_folder else out)
    camera = make_camera(args)
    check_error(args.error)
    raytrace = args.method == "raytrace"
    if raytrace:
        if args.field != "bspline":
            raise InputError("progressive ray tracing takes the B-spline field; leave out --field")
        if (args.steps, args.budget) != (None, None):  # else every frame of its schedule
            check_schedule(args.steps, args.budget)
        steps = args.steps
        options = dict(tolerance=args.tolerance, lights=parse_lights(args), shading=not args.no_shading,
                       absorption=not args.xray)
    else:
        steps = 8 if args.steps is None and args.budget is None else args.steps
        check_schedule(steps, args.budget)
        options = dict(omega_s=args.omega_s, coarse=args.coarse or None)
    background, window, device_memory = look["background"], look["window"], parse_device_memory(args)
    wv, _ = build_model(args, rgba=raytrace and not args.xray, noise=True)
    camera = opened(args, camera, wv)
    check_picture_fits(look, camera, wv, xray=not raytrace or args.xray)
    if raytrace:
        options["clip"] = parse_clip(args, wv)  # --clip-voxels: in the model's geometry
    if raytrace and not args.xray:
        options["transfer_function"] = post_transfer_function(args, wv)  # a scalar model: classified while rendering
    elif raytrace:  # line integrals of the whole model, as splatting draws them (docs/raytracing.md §1)
        from ..raytrace.tracer import RayTracer

        options["tracer"] = RayTracer(wv, device=args.device, device_memory=device_memory, content_clamp=False)
    frames = list(progress(progressive(wv, camera, steps=steps, budget=args.budget, device=args.device,
                                       method=args.method, error=args.error, device_memory=device_memory, **options),
                           total=steps, desc="progressive frames"))
    if frames[-1].meta.get("nothing_visible"):  # every frame blank: not what was asked for (docs/raytracing.md §10)
        raise InputError(frames[-1].meta["nothing_visible"])
    if window == "auto" and frames[-1].result().is_xray:  # the final image's window for every frame
        window = resolve_window(frames[0].final_image()[..., :3], "auto", look["colour_map"])
    figures = [f.figures() for f in frames]
    with published_together() as outputs:  # every output written, then all published (coordinates.md §4)
        if as_folder:  # written beside it, renamed into place: never mixed with another run's frames
            out.parent.mkdir(parents=True, exist_ok=True)
            folder = outputs.folder(out, args.force, replaces=r"frame_\d{3,}\.png")
            for f in frames:
                f.save(folder / f"frame_{f.index:03d}.png", window=window, background=background,
                       bit_depth=look["bit_depth"], scale_bar=look["scale_bar"], colour_map=look["colour_map"],
                       colour_bar=look["colour_bar"])
        else:
            write_gif(out, [f.result().picture(window, background, scale_bar=look["scale_bar"],
                                               colour_map=look["colour_map"], colour_bar=look["colour_bar"])
                            for f in frames], 0.5, args.force)
        if args.stats:
            meta = dict(frames[-1].meta, window=frames[-1].result().display_window(window))  # as render's (§4)
            text = json.dumps(dict(frames=figures, meta=meta), indent=2, default=str).encode()
            write_atomic(args.stats, lambda fh: fh.write(text), args.force)
        finish(outputs, [_report(f, raytrace) for f in figures])
    return 0


def _report(f, raytrace) -> str:
    """The line of one frame's figures."""
    what = (f"detail {f['detail']} on a 1/{f['reduction']} image" if raytrace else
            f"{f['coefficients']:>10,} coefficients ({100 * f['fraction']:6.2f} % of those kept, "
            f"{100 * f['voxel_fraction']:.3f} % of the voxels)")
    return (f"frame {f['index']}: {what} at {f['seconds']:.3f} s; error against the final image: RMS "
            f"{f['relative_rms_error']:.2e} (estimated {f['estimated_relative_rms_error']:.2e}), max "
            f"{f['relative_max_error']:.2e} (estimated {f['estimated_relative_max_error']:.2e}) of its largest value")


def add_parser(sub):
    p = add_command(sub, "progressive", "progressive frames, cheap to exact, as a GIF or a folder of PNGs", run,
                    "output .gif, or a folder for PNG frames", view=True)
    p.add_argument("--method", choices=["splat", "raytrace"], default="splat",
                   help="splat (default): coefficients by importance; raytrace: full detail on reduced images "
                        "first, ending at the direct render (needs a classified model, or --xray)")
    add_raytrace_options(p)
    k = p.add_mutually_exclusive_group()
    k.add_argument("--steps", type=int, help="number of frames (splatting: default 8; ray tracing: the last N)")
    k.add_argument("--budget", type=float, help="seconds: stop when the next step would not fit")
    p.add_argument("--error", type=float, help="stop at the first frame whose estimated relative RMS error is "
                                               "at most this, e.g. 0.01")
    p.add_argument("--stats", help="per-frame figures as .json")
