"""``clwave render``: one image (or a turntable) by splatting or ray tracing."""

from __future__ import annotations

import contextlib

import numpy as np

from ..errors import InputError
from .checks import (check_picture_fits, make_camera, opened, parse_clip, parse_lights, parse_turntable_axis,
                     picture_options)
from .options import (add_command, add_raytrace_options, build_model, check_outputs, finish, is_clw,
                      parse_device_memory, parse_scheduler, post_transfer_function)


def run(args):
    from ..raytrace.tracer import RayTracer, raytrace
    from ..io.files import published_together
    from ..io.images import PNG_SUFFIXES, TIFF_SUFFIXES
    from ..io.result import RenderResult
    from ..splat.renderer import SplatRenderer, splat
    from ..cluster import check_model_file
    from ..schedulers import client_for as cluster_client
    from ..turntable import Turntable, turntable_cameras

    picture = PNG_SUFFIXES + TIFF_SUFFIXES if args.turntable is None else (".gif",)
    hint = "--raw OUT.npy also writes the float32 image" if args.turntable is None else "--turntable writes a GIF"
    out, raw, stats = check_outputs(args.force, (args.output, "-o", picture, hint), (args.raw, "--raw", (".npy",)),
                                    (args.stats, "--stats", (".json",)))
    look = picture_options(args, out)
    if args.edge_labels and (args.turntable is not None or out.suffix.lower() not in PNG_SUFFIXES):
        raise InputError("--edge-labels writes letters into a PNG picture: give -o OUT.png, without --turntable")
    window, background = look["window"], look["background"]
    camera = make_camera(args)
    axis = None if args.turntable is None else parse_turntable_axis(args)
    if axis is not None:  # their memory checked before the input is read
        turntable_cameras(camera, args.turntable, axis)
    device_memory = parse_device_memory(args)
    lights = parse_lights(args)
    on_cluster = is_clw(args) and (args.workers, args.scheduler) != (None, None)
    wv, _ = build_model(args, rgba=args.method == "raytrace" and not args.xray, cluster_render=on_cluster, noise=True)
    camera = opened(args, camera, wv)
    if args.edge_labels:  # the viewer's letters (view/orientation.py), for its view's command
        from ..view.export import Origin
        from ..view.orientation import edges, patient_world

        look["edge_labels"] = edges(camera, patient_world(wv, Origin.of_args(args)))
    cameras = [camera] if args.turntable is None else turntable_cameras(camera, args.turntable, axis)
    check_picture_fits(look, camera, wv, xray=args.method != "raytrace" or args.xray)
    if on_cluster:  # docs/raytracing.md §7, docs/splatting.md §7: each worker opens the file
        from ..raytrace.regions import check_cluster_model

        if args.method == "raytrace":
            check_cluster_model(wv, args.field)
        else:
            check_model_file(wv, "splatting")
    cluster = cluster_client(parse_scheduler(args)) if on_cluster else contextlib.nullcontext()
    if args.detail and args.detail > wv.levels:  # docs/raytracing.md §8: the bricks of that detail alone
        raise InputError(f"--detail {args.detail} must be a level from 0 (full detail) to {wv.levels}, the model's "
                         f"coarsest")
    if args.method == "raytrace":
        options = dict(tolerance=args.tolerance, lights=lights, shading=not args.no_shading,
                       absorption=not args.xray, clip=parse_clip(args, wv),
                       transfer_function=None if args.xray else post_transfer_function(args, wv))
        if on_cluster:
            options.update(device=args.device, field=args.field, device_memory=device_memory)
        else:
            # --xray: line integrals of the whole model, as splatting draws them (docs/raytracing.md §1)
            tracer = RayTracer(wv, device=args.device, field=args.field, device_memory=device_memory,
                               content_clamp=not args.xray, lod=(args.detail,) if args.detail else False)

        def render(cam):
            if on_cluster:
                return raytrace(wv, cam, scheduler=client, **options)
            return tracer.render(cam, detail=args.detail, **options)
    else:
        eight_bit = out.suffix.lower() in PNG_SUFFIXES + (".gif",) and look["bit_depth"] in (None, 8)
        options = dict(device=args.device, omega_s=args.omega_s, device_memory=device_memory,
                       coarse=splat_coarse(args.coarse, eight_bit and raw is None and window == "auto"))
        if not on_cluster:
            options = dict(renderer=SplatRenderer(wv, **options))

        def render(cam):
            return splat(wv, cam, scheduler=client, **options)
    with cluster as client:
        turn = Turntable.rendered(render, cameras)
    if turn[0].meta.get("nothing_visible"):  # a blank image is not what was asked for (docs/raytracing.md §10)
        raise InputError(turn[0].meta["nothing_visible"])
    with published_together() as outputs:  # every output written, then all published (coordinates.md §4)
        lines = []
        if args.turntable is None:
            result = turn[0]
            result.save(out, **look, overwrite=args.force)
        else:
            # resolved once: the pictures' and --stats' window
            window = turn.window(window, look["colour_map"]) or window
            turn.save(out, window=window, background=background, scale_bar=look["scale_bar"],
                      colour_map=look["colour_map"], colour_bar=look["colour_bar"],
                      frame_time=args.frame_time or 0.1, overwrite=args.force)
            result = RenderResult(turn[0].image, turn.meta)
            seconds = result.meta["turntable_seconds"]
            views = f"{len(turn)} view{'s' if len(turn) != 1 else ''}"
            lines.append(f"turntable of {views} at {camera.size[0]}x{camera.size[1]} in {sum(seconds):.3f} s "
                         f"({np.median(seconds):.3f} s a view, median); the first view:")
        # the picture's, for --stats (coordinates.md §4): a .tif has none
        result.meta["window"] = None if out.suffix.lower() in TIFF_SUFFIXES else \
            result.display_window(window, look["colour_map"])
        if raw is not None:  # a turntable's views as one (N, H, W, C) array
            (result if args.turntable is None else turn).save(raw, overwrite=args.force)
        if stats is not None:
            result.save(stats, overwrite=args.force)
        finish(outputs, lines + [_report(args, camera, result.meta, out)])
    return 0


#: ``clwave render``'s splatting tolerance where it writes 8-bit pictures only, through the automatic window, and
#: ``--coarse`` is not given: coarse framebuffers then move a pixel of the picture by one level at most (a level is
#: 1/255 of the window, which spans 0.8 of the image maximum or more) for 2-3.5x less CPU time from 512^2 to 1024^2
#: (docs/splatting.md §4 "The command line's default")
EIGHT_BIT_COARSE = 1e-3


def splat_coarse(coarse, eight_bit_auto: bool):
    """The splat renderer's ``coarse``: ``--coarse`` where given (0: off), else :data:`EIGHT_BIT_COARSE` where every
    image written is an 8-bit picture through the automatic window (``eight_bit_auto``), else None (every band at
    the image's pixels: ``--raw``'s float32 values, a .tif's, a 16-bit PNG, or a window narrower than the image's
    values)."""
    if coarse is not None:
        return coarse or None
    return EIGHT_BIT_COARSE if eight_bit_auto else None


def _report(args, camera, m, out) -> str:
    """The line that says what was rendered, how fast, and where to."""
    size = f"{camera.size[0]}x{camera.size[1]}"
    if args.method == "raytrace":
        where = f"on {m['workers']} workers in {len(m['slabs'])} slabs" if "slabs" in m else \
            f"{m['rays_terminated_early']:,} rays terminated early"
        return (f"ray traced {size} ({m['mode']}, {m['field']} field, tolerance {m['tolerance']:g}, shading "
                f"{m['shading']}) in {m['render_seconds']:.3f} s: {m['segments']:,} segments, {where} (set-up "
                f"{m['setup_seconds']:.2f} s and kernel build {m['compile_seconds']:.2f} s apart) -> {out}")
    s = m["seconds"]
    return (f"splatted {m['coefficients']:,} coefficients at {size} in {s['total']:.3f} s (footprints "
            f"{s['footprints']:.3f}, binning {s['binning']:.3f}, accumulation {s['accumulation']:.3f}; "
            f"kernel build {s['compile']:.2f} s apart) -> {out}")


def add_parser(sub):
    p = add_command(sub, "render", "render an image: wavelet splatting (X-ray) or ray tracing (shaded)", run,
                    "output .png, always written (--raw adds the float32 values beside it), or .tif/.tiff (the float32 "
                    "values, no window); .gif with --turntable",
                    view=True)
    p.add_argument("--method", choices=["splat", "raytrace"], default="splat",
                   help="splat (default): X-ray line integrals; raytrace: emission-absorption, shaded (needs a "
                        "classified model: --tf, or a .clw compressed with it; a scalar .clw takes --tf to classify "
                        "while rendering; or --xray)")
    add_raytrace_options(p)
    p.add_argument("--detail", type=int, help="ray tracing: the level of detail, 0 (full, the default) up to the "
                                              "model's levels (the coarsest: its approximation alone, fastest)")
    p.add_argument("--turntable", type=int, metavar="N", help="write an N-frame rotation GIF: the camera turned "
                                                              "through 360 degrees about --turntable-axis")
    p.add_argument("--turntable-axis", metavar="x|y|z|AX,AY,AZ",
                   help="with --turntable: the world axis turned about, right-handed (default z: the azimuth turned, "
                        "the elevation kept), or a direction")
    p.add_argument("--frame-time", type=float, metavar="SECONDS",
                   help="with --turntable: the seconds each frame is shown, 0.02 to 655.35, to the hundredth "
                        "(default 0.1)")
    p.add_argument("--edge-labels", action="store_true",
                   help="PNG: write which way the view faces at the picture's edges, as clwave view shows them and "
                        "saves them (R/L, A/P, S/I for a patient's volume: --orientation, or DICOM, NIfTI, NRRD, MGH; "
                        "else +x/-x, +y/-y, +z/-z)")
    p.add_argument("--raw", help="also write the float32 image as .npy (with --turntable, its N views as one "
                                 "(N, H, W, C) array)")
    p.add_argument("--stats", help="also write the figures as .json")
