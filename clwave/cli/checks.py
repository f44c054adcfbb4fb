"""The options checked before the input is opened (:func:`check_options`, which the command line runs first), and
the view's options read from their text: lights, background, display window and the image size."""

from __future__ import annotations

import numpy as np

from ..errors import InputError, float32_number
from ..io.result import check_background
from ..model.tf_checks import check_opacity_unit, check_window
from ..io.images import check_frame_time
from .options import (is_clw, parse_device_memory, parse_scheduler, parse_tf_window, parse_thresholding,
                      preset_transfer_function)
from .reading import flag, numbers, parse_chunks, parse_spacing


#: the options given as one number (argparse's ``type=float``) whose own checks (below, or in the model's API words)
#: do not refuse what is not finite (argparse takes "nan" and "inf")
NUMBERS = ("azimuth", "elevation", "fov", "distance", "extent", "keep", "threshold", "noise", "sigma", "subtract",
           "nan", "dso", "dsd", "error")


def check_options(args):
    """Every option the commands share whose validity does not depend on the input, checked before the input is
    opened, so that a mistake costs no read (a command's own options its ``run`` checks first thing): numbers that
    are not finite, the input's spacing and chunks, the model's wavelets, levels, thresholding, transfer function and
    classification, the scheduler, and the view's device, display window, footprint band, coarse tolerance, a
    turntable's frame time, device memory, ray tracing tolerance, lights, clip and background, the options of the
    --method not chosen, and the image size against the device (:func:`check_image_size`).  An option a command does
    not have is not looked at."""
    from ..model.bspline import wavelet_for

    if getattr(args, "input", getattr(args, "file", None)) is None:  # clwave info without FILE: no input to spare
        return
    for name in NUMBERS:
        value = getattr(args, name, None)
        if value is not None and not np.isfinite(value):
            raise InputError(f"{flag(name)} {value:g} must be a finite number")
    for name in ("subtract", "nan"):  # applied to the float32 values as they are read
        if getattr(args, name, None) is not None:
            float32_number(getattr(args, name), name)
    if getattr(args, "spacing", None) is not None:
        parse_spacing(args.spacing)
    if getattr(args, "chunks", None) is not None:
        parse_chunks(args.chunks)
    if not hasattr(args, "input"):  # clwave info FILE: its reading options alone (it echoes them)
        return
    if getattr(args, "wavelet", None) is not None:
        for name in args.wavelet.split(","):
            wavelet_for(name)
    if getattr(args, "levels", None) is not None and args.levels < 0:
        raise InputError(f"--levels {args.levels} must be 0 or more (at most floor(log2(shortest axis)) - 1)")
    if hasattr(args, "keep"):
        parse_thresholding(args)
    if hasattr(args, "tf"):
        if args.tf_window is not None:
            check_window(parse_tf_window(args.tf_window), "--tf-window")
        check_opacity_unit(args.opacity_unit, "--opacity-unit")
        if args.tf or not is_clw(args):  # a .clw's own transfer function takes --tf-window alone
            preset_transfer_function(args)
        if args.classify == "post" and not args.tf and not is_clw(args):
            raise InputError("--classify post keeps the scalar for ray tracing to classify with the --tf preset: "
                             "give --tf PRESET too")
    if hasattr(args, "workers"):
        parse_scheduler(args)
    if hasattr(args, "device") and not (is_clw(args) and args.scheduler):  # a remote cluster's workers choose theirs
        from ..device.context import select_device
        select_device(args.device)
    if hasattr(args, "display_window"):
        parse_window(args)
    if getattr(args, "detail", None) is not None:  # the levels the model has are known once it is read
        if args.detail < 0:
            raise InputError(f"--detail {args.detail} must be a level of detail: 0 (full) up to the model's levels")
        if args.detail and (args.field == "wavelet" or (args.workers, args.scheduler) != (None, None)):
            raise InputError("--detail renders with the B-spline field on one machine: leave out --field wavelet "
                             "and --workers/--scheduler, or --detail")
    if getattr(args, "omega_s", None) is not None:
        from ..splat.textures import check_omega_s

        check_omega_s(args.omega_s)
    if getattr(args, "frame_time", None) is not None:
        _frame_time(args)
    if hasattr(args, "turntable_axis"):
        parse_turntable_axis(args)
    if getattr(args, "coarse", None) is not None and not 0 <= args.coarse < 1:
        raise InputError(f"--coarse {args.coarse:g} must be a tolerance between 0 and 1, e.g. 1e-2, or 0 (off)")
    if hasattr(args, "device_memory"):
        parse_device_memory(args)
    if hasattr(args, "method"):
        _method_options(args)
    if getattr(args, "tolerance", None) is not None and not (np.isfinite(args.tolerance) and args.tolerance > 0):
        raise InputError(f"--tolerance {args.tolerance:g} must be a positive absolute error, e.g. 1e-3")
    if getattr(args, "light", None) is not None:
        parse_lights(args)
    parse_clip(args)
    if hasattr(args, "background"):
        parse_background(args)
    if hasattr(args, "method") and not (is_clw(args) and (args.workers, args.scheduler) != (None, None)):
        from ..device.memory import FRAMEBUFFER_PIXEL_BYTES, TRACED_PIXEL_BYTES
        # render, progressive and drr; a cluster's workers hold their images
        check_image_size(parse_size(args), args.device,
                         TRACED_PIXEL_BYTES if args.method == "raytrace" else FRAMEBUFFER_PIXEL_BYTES)


#: options of one --method only, refused with the other (a command has some of them: drr has no --light);
#: (option, what it is given when not given: None where the command leaves it None)
RAYTRACE_ONLY = (("tolerance", 1e-3), ("light", None), ("no_shading", None), ("xray", None), ("field", "bspline"),
                 ("background", None), ("detail", None), ("clip_box", None), ("clip_voxels", None),
                 ("clip_plane", None))
SPLAT_ONLY = ("coarse", "omega_s")


def _method_options(args):
    """Refuse the options of the --method not chosen (silently ignored otherwise), then give those of ray tracing
    that were not given their defaults (their parsers leave them None, so that a given one is told)."""
    other = [n for n, _ in RAYTRACE_ONLY] if args.method == "splat" else SPLAT_ONLY
    given = [flag(n) for n in other if getattr(args, n, None) not in (None, False)]
    named, verb, them = ", ".join(given), *(("is", "it") if len(given) == 1 else ("are", "them"))
    if given and args.method != "splat":
        raise InputError(f"{named} {verb} for --method splat; ray tracing controls its error with --tolerance")
    shaded = [flag(n) for n in ("background", "light", "no_shading") if getattr(args, n, None) not in (None, False)]
    if getattr(args, "xray", False) and shaded and args.method != "splat":
        verb, it = ("are", "them") if len(shaded) > 1 else ("is", "it")
        raise InputError(f"{', '.join(shaded)} {verb} for a shaded volume; an X-ray (--xray) is line integrals, shown "
                         f"through --window: leave {it} out")
    if getattr(args, "no_shading", False) and getattr(args, "light", None):
        raise InputError("--light lights a shaded image; an unshaded image (--no-shading) has none, so it changes "
                         "nothing: leave it out")
    if getattr(args, "display_window", "auto") != "auto" and args.method != "splat" and not getattr(args, "xray", 0):
        raise InputError(f"--window {args.display_window} windows an X-ray's line integrals; a shaded image is "
                         f"written as its colours: add --xray, or leave --window out")
    if given:
        raise InputError(f"{named} {verb} for --method raytrace; splatting ignores {them}: add --method raytrace, or "
                         f"leave {them} out")
    for name, default in RAYTRACE_ONLY:  # those the command has (add_raytrace_options, drr's --tolerance)
        if hasattr(args, name) and getattr(args, name) is None:
            setattr(args, name, default)


def parse_turntable_axis(args):
    """``--turntable-axis x|y|z|AX,AY,AZ`` as :func:`clwave.turntable` takes ``axis`` ("z" when not given)."""
    from ..turntable import AXES, turntable_axis

    text = args.turntable_axis
    if text is None:
        return "z"
    if args.turntable is None:
        raise InputError("--turntable-axis is for a --turntable: add --turntable N, or leave it out")
    if text in AXES:
        return text
    try:
        direction = numbers(text, "--turntable-axis", (3,))
    except InputError:
        raise InputError(f"--turntable-axis {text} must be x, y, z or three numbers AX,AY,AZ") from None
    turntable_axis(direction)  # a direction: not all zero
    return direction


def _frame_time(args):
    """``--frame-time SECONDS``: a turntable GIF's, within what a GIF holds and browsers show (NaN fails both)."""
    check_frame_time(args.frame_time)
    if args.turntable is None:
        raise InputError("--frame-time is for a --turntable GIF: add --turntable N, or leave it out")


def parse_lights(args):
    if args.light is None:
        return None
    if args.light == ["none"]:
        return []
    lights = [tuple(numbers(spec, "--light", (2,))) for spec in args.light]
    for spec, light in zip(args.light, lights):
        if not all(np.isfinite(light)):
            raise InputError(f"--light {spec} must be two finite angles AZ,EL in degrees, e.g. 30,20")
    return lights


def parse_clip(args, wv=None):
    """The :class:`~clwave.Clip` of ``--clip-box X0,Y0,Z0,X1,Y1,Z1`` or ``--clip-voxels Z0:Z1,Y0:Y1,X0:X1`` (of the
    model ``wv``'s input array: :meth:`~clwave.Clip.of_voxels`; without ``wv``, before it is made, only read) and the
    ``--clip-plane PX,PY,PZ,NX,NY,NZ`` s (None where none is given, or the command has none)."""
    from ..model.clip import Clip
    from ..model.geometry import voxel_ranges

    box, voxels = getattr(args, "clip_box", None), getattr(args, "clip_voxels", None)
    planes = getattr(args, "clip_plane", None) or []
    if box is None and voxels is None and not planes:
        return None
    if box is not None and voxels is not None:
        raise InputError(f"--clip-box {box} and --clip-voxels {voxels} each give the box: give one of them")
    given = ([f"--clip-box {box}"] if box is not None else []) + \
        ([f"--clip-voxels {voxels}"] if voxels is not None else []) + [f"--clip-plane {p}" for p in planes]
    corners = numbers(box, "--clip-box", (6,)) if box is not None else None
    faces = [numbers(p, "--clip-plane", (6,)) for p in planes]
    try:
        if voxels is None:
            return Clip.of_rows(corners, faces)
        if wv is None:
            return voxel_ranges(voxels)
        return Clip.of_voxels(wv, voxels, getattr(args, "orientation", None), [(p[:3], p[3:]) for p in faces])
    except InputError as error:
        raise InputError(f"{' '.join(given)}: {error}") from None


def parse_background(args):
    """The colour (R, G, B) of ``--background``, each in 0..1, or "transparent" (None: not given, the default
    black)."""
    if args.background is None or args.background == "transparent":
        return args.background
    return check_background(numbers(args.background, "--background", (3,)))


def picture_options(args, out) -> dict:
    """``window``, ``background``, ``bit_depth``, ``scale_bar``, ``colour_map`` and ``colour_bar`` of the picture
    written to ``out`` (a folder: PNG frames), for :meth:`~clwave.io.result.RenderResult.save`; refused in one line
    where ``out`` holds no such picture: a .tif's or .npy's values as rendered, a GIF's 8-bit frames without partial
    transparency."""
    from ..io.images import TIFF_SUFFIXES, check_bit_depth, check_orthographic, check_scale_bar
    from ..view.colours import check_colour_map

    look = dict(window=parse_window(args), background=parse_background(args) if hasattr(args, "background") else None,
                bit_depth=args.bit_depth, scale_bar=check_scale_bar(getattr(args, "scale_bar", None)),
                colour_map=check_colour_map(args.colour_map), colour_bar=args.colour_bar)
    check_bit_depth(args.bit_depth)
    if look["scale_bar"] is not None:
        check_orthographic(dict(kind="camera", perspective=args.perspective))
    suffix = out.suffix.lower()
    if suffix in TIFF_SUFFIXES + (".npy",):
        given = {"--window": look["window"] != "auto", "--background": look["background"] is not None,
                 "--bit-depth": args.bit_depth is not None, "--scale-bar": look["scale_bar"] is not None,
                 "--colour-map": look["colour_map"] is not None, "--colour-bar": look["colour_bar"]}
        named = [name for name, there in given.items() if there]
        what = {"--window": "grey levels", "--background": "background", "--bit-depth": "bit depth",
                "--scale-bar": "scale bar", "--colour-map": "colours", "--colour-bar": "colour bar"}
        if named:
            raise InputError(f"{' and '.join(named)} {'sets' if len(named) == 1 else 'set'} a .png's "
                             f"{' and '.join(what[n] for n in named)}; a {suffix} holds the values themselves: leave "
                             f"{'it' if len(named) == 1 else 'them'} out")
    if suffix == ".gif" and args.bit_depth is not None:
        raise InputError(f"--bit-depth {args.bit_depth} is for PNG; a GIF holds 8 bits a sample: leave it out"
                         + (", or write PNG frames to a folder" if args.command == "progressive" else ""))
    if suffix == ".gif" and look["background"] == "transparent":
        raise InputError("--background transparent is for PNG; a GIF has no partial transparency: give a colour R,G,B"
                         + (", or write PNG frames to a folder" if args.command == "progressive" else ""))
    return look


def check_picture_fits(look, camera, wv, xray):
    """Refuse, before the render, a ``--scale-bar`` that does not fit ``camera``'s picture of ``wv`` (as
    :func:`~clwave.io.images.draw_scale_bar` would after it), a ``--colour-map`` for a picture it does not colour
    (an ``xray`` of ``wv``'s channels or a shaded one: :func:`~clwave.io.result.check_colour_mapped`), and a
    ``--colour-bar`` where it keys nothing (:func:`~clwave.io.result.check_colour_barred`) or has no room."""
    from ..io.images import draw_colour_bar, draw_scale_bar
    from ..io.result import check_colour_barred, check_colour_mapped

    if look["colour_map"] is not None:
        check_colour_mapped(look["colour_map"], xray, wv.channels, look["bit_depth"])
    if look["colour_bar"]:
        check_colour_barred(xray, wv.channels)
        if camera is not None:  # a picture too small for it with the shortest labels (the window is the image's)
            draw_colour_bar(np.zeros(camera.size, np.uint8), lambda f: np.zeros(f.shape, np.uint8), (0, 1))
    if look["scale_bar"] is not None:
        draw_scale_bar(np.zeros(camera.size, np.uint8), camera.view(wv).pixel, wv.unit, look["scale_bar"])


def parse_window(args):
    """``--window auto|LO,HI``: "auto", or two finite numbers LO < HI (checked before any work)."""
    return check_window(args.display_window if args.display_window == "auto" else
                        numbers(args.display_window, "--window", (2,)), "--window", getattr(args, "colour_map", None))


def parse_size(args) -> tuple:
    """The image's (H, W) from ``--size N`` or ``--size HxW``, each a positive whole number of pixels."""
    size = numbers(args.size.lower(), "--size", (1, 2), int, sep="x")
    if min(size) < 1:
        raise InputError(f"--size {args.size} must be a positive number of pixels N or HxW, e.g. 512 or 300x400")
    return size * 2 if len(size) == 1 else size


def check_image_size(size, device, pixel_bytes, image="a {} image"):
    """Refuse an image of ``size`` (H, W) beyond the device's own limit on the one buffer its renderer holds for it,
    ``pixel_bytes`` a pixel (device/memory.py: splatting's framebuffer, ``FRAMEBUFFER_PIXEL_BYTES``; the ray tracer's
    image, ``TRACED_PIXEL_BYTES``), or beyond the host's memory (:func:`~clwave.device.memory.check_image`), naming
    the largest square that fits; ``image``: what the message calls it, "HxW" in its braces.  What depends on the
    model is the renderer's to check: ``--coarse``'s extra framebuffers, and the least ``--device-memory`` (the ray
    tracer's bricks with the image).  Returns the device's context, made here."""
    from ..device.context import ComputeContext
    from ..device.memory import check_image

    (H, W), cc = size, ComputeContext.get(device)
    check_image(cc, size, H * W * pixel_bytes, "give a smaller --size (at most {n}x{n} here)",
                what=image.format("{}x{}"))
    return cc


def make_camera(args):
    from ..model.camera import Camera

    return Camera(**view_angles(args), size=parse_size(args), extent=args.extent, fit=args.fit,
                  perspective=args.perspective, distance=args.distance, fov=args.fov)


def opened(args, camera, wv):
    """``camera`` (:func:`make_camera`'s) turned to the model's opening view
    (:func:`~clwave.model.camera.opening_view`: a slab's face) where none of ``--view``, ``--azimuth`` and
    ``--elevation`` was given."""
    import copy

    from ..model.camera import opening_view

    if (args.view, args.azimuth, args.elevation) != (None, None, None):
        return camera
    camera = copy.copy(camera)
    camera.__dict__.update(opening_view(wv))
    return camera


def view_angles(args) -> dict:
    """``dict(azimuth=, elevation=)`` of ``--view NAME`` (:func:`~clwave.model.geometry.named_view`), or of
    ``--azimuth`` and ``--elevation`` (each the default, :data:`~clwave.model.camera.OPENING`, where not given); both
    kinds refused in one line."""
    from ..model.camera import OPENING
    from ..model.geometry import named_view

    default = OPENING

    given = [f"--{name}" for name in ("azimuth", "elevation") if getattr(args, name, None) is not None]
    if args.view is None:
        return dict(azimuth=default[0] if args.azimuth is None else args.azimuth,
                    elevation=default[1] if args.elevation is None else args.elevation)
    if given:
        raise InputError(f"--view {args.view} sets the azimuth and elevation that {' and '.join(given)} "
                         f"set{'s' * (len(given) == 1)}: give one or the other")
    return named_view(args.view)
