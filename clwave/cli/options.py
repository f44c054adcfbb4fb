"""What the commands share: the input made into a wavelet model (read as :mod:`.reading` says), the view and output
options."""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from pathlib import Path

from ..errors import ClwaveWarning, CommandWords, InputError, NoisyModelWarning, OutputError, OutputExistsError
from ..io.files import check_writable
from ..model.transform import DEFAULT_LEVELS
from ..model.wavelet import DEFAULT_KEEP
from .reading import READING, add_input_options, flag, is_given, numbers, option, read_volume

DEFAULT_WAVELET = "cubic"


def warn(text: str):
    """One warning line on stderr, as every command says what it did other than asked (never a traceback)."""
    print(f"clwave: warning: {text}", file=sys.stderr)


def add_model_options(p, classify=True):
    """The options that make a wavelet model of a volume; ``classify``: with the transfer function's (``--tf``,
    ``--tf-window``, ``--classify``), which ``drr`` has not (a radiograph integrates the scalar itself)."""
    from ..model.transfer import TransferFunction

    g = p.add_argument_group("wavelet model (from a volume; a .clw input is a model already)")
    g.add_argument("--wavelet", help=f"haar, linear, quadratic, cubic or quintic; or one per channel, comma-separated "
                                     f"(default {DEFAULT_WAVELET})")
    g.add_argument("--levels", type=int, help=f"decomposition levels (default {DEFAULT_LEVELS}, or as many as a "
                                              "small volume allows)")
    k = g.add_mutually_exclusive_group()
    k.add_argument("--keep", type=float, help=f"fraction of voxels kept as coefficients, (0, 1] (default "
                                              f"{DEFAULT_KEEP} for a volume; 1 keeps every coefficient)")
    k.add_argument("--threshold", type=float, help="keep coefficients above this importance")
    k.add_argument("--noise", type=float, help="keep each detail above this many times the noise of its band, the "
                                               "noise measured in the finest band (e.g. 3 on a noisy volume; "
                                               "docs/model.md §2)")
    g.add_argument("--focus", help="local level of detail: world centre X,Y,Z (needs --sigma)")
    g.add_argument("--sigma", type=float, help="local level of detail: Gaussian width (world units)")
    g.add_argument("--interpolate", action="store_true",
                   help="interpolating instead of approximating model: through the voxels' values (it rings at edges)")
    if not classify:
        return
    g.add_argument("--tf", help="classify with a transfer function first: a preset ("
                                + ", ".join(TransferFunction.PRESETS) + ") or a FILE.json or .csv of (value, r, g, b, "
                                "opacity) rows, or (label, r, g, b, opacity) rows for a label map (docs/model.md §5)")
    g.add_argument("--tf-window", help="transfer-function window: auto (percentiles of the values) or LO,HI in "
                   "the input's units (HU for CT, attenuation per mm with --hu-to-mu; with or without --subtract); "
                   "a colour volume's in its luminance, 0 .. 1 whatever its sample type")
    g.add_argument("--opacity-unit", type=float, metavar="LENGTH",
                   help="the length (world units, the spacing's) that --tf's opacities are per; default one voxel "
                        "(the smallest spacing), so a volume looks the same in um or mm (docs/model.md §5)")
    g.add_argument("--key", metavar="R,G,B[,TOL]|auto",
                   help="with --tf, a colour volume's background colour made transparent (a gel, ice): R,G,B in its "
                        "sample units (0 .. 255 for 8 bits), transparent within TOL of it (default 0.1 of the range) "
                        "and fully opaque from twice TOL; auto: the median colour of the box's edges (docs/model.md "
                        "§5)")
    g.add_argument("--classify", choices=("pre", "post"), default="pre",
                   help="with --tf: pre (default) classifies the volume before the transform; post keeps the "
                        "scalar and the transfer function for ray tracing to classify while rendering: the model's "
                        "values, which average each voxel with its neighbours, so a layer a voxel or two thick may "
                        "peak below a threshold its voxels pass (--interpolate: the model through the voxels; "
                        "docs/model.md §5) (a .clw input: --tf always classifies while rendering)")


def is_clw(args) -> bool:
    """Whether the input is a ``.clw`` file (a wavelet model already)."""
    return args.input.lower().endswith(".clw")


def parse_scheduler(args):
    """The Dask scheduler of chunked work: ``--workers N``, ``--scheduler ADDRESS`` or threads (None)."""
    from ..schedulers import check_scheduler

    return check_scheduler(args.workers if args.workers is not None else args.scheduler)


#: the options of the transfer function, which a scalar .clw takes to classify while rendering
TF_OPTIONS = ("tf", "tf_window", "opacity_unit")
#: options that make a model from a volume, and so cannot apply to a .clw input (a model already)
VOLUME_ONLY = (*TF_OPTIONS, "key", "wavelet", "levels", "interpolate") + READING + ("workers", "scheduler")


def parse_thresholding(args) -> dict:
    """``threshold()`` arguments from ``--keep``, ``--threshold``, ``--noise``, ``--focus``/``--sigma``, checked before
    any work."""
    from ..model.budget import check_thresholding

    focus = None
    if args.focus is not None or args.sigma is not None:
        if args.focus is None or args.sigma is None:
            raise InputError("--focus X,Y,Z and --sigma S go together")
        if args.keep is None and args.threshold is None and args.noise is None and is_clw(args):
            raise InputError("--focus selects where detail is kept: give --keep, --threshold or --noise too")
        focus = (numbers(args.focus, "--focus", (3,)), args.sigma)
    keep, threshold, focus, noise = check_thresholding(args.keep, args.threshold, focus, args.noise)
    return dict(keep=keep, threshold=threshold, focus=focus, noise=noise)


def _needs_rgba(name, channels, fix) -> InputError:
    return InputError(f"shaded ray tracing needs a classified (RGBA, 4 channels) model, {name} has {channels} "
                      f"channel(s): {fix}, or render line integrals with --xray")


def build_model(args, log=print, rgba=False, gather=True, cluster_render=False, opener=None, post=False,
                hu_hint=True, volume=None, noise=False):
    """Read, classify (``--tf``), decompose and threshold as the options say; every option is
    checked before the work starts.  ``rgba``: the caller needs 4 channels (shaded ray tracing).
    ``post`` (implied by ``rgba``): a scalar ``.clw`` input takes ``--tf``/``--tf-window``, the transfer function
    the caller classifies with while rendering (:func:`post_transfer_function`).

    Returns ``(wavelet_volume, reference_volume)``; the reference is the volume the
    model approximates (None when the input was already a ``.clw`` file).  A chunked input gives no
    reference, and with ``gather`` false a :class:`~clwave.model.chunked.ChunkedWaveletVolume`
    (thresholded, not gathered).  ``cluster_render``: a ``.clw`` input takes ``--workers``/``--scheduler``
    (the render runs there).  ``opener``: a ``.clw`` input with ``--keep`` alone (or none) is ``opener(path, keep)``
    instead of the model read (``clwave view`` opens it by its prefix first).  ``hu_hint``: a volume (chunked too) that
    looks like CT in Hounsfield units gets a warning (docs/coordinates.md §1).  ``volume``: the input read already
    (:func:`read_volume`), for a caller that reports on it.  ``noise``: a volume read whole has its noise measured
    (:meth:`~clwave.WaveletVolume.measure_noise`, before thresholding), for a caller that records it."""
    from ..io.loaders.shared import air_in_hounsfield
    from ..model.transfer import TransferFunction
    from ..model.budget import warn_stored
    from ..model.transform import check_decomposition, default_levels
    from ..model.wavelet import WaveletVolume

    thresholding = parse_thresholding(args)
    scheduler = parse_scheduler(args)
    if is_clw(args):
        given = [option(args, name) for name in VOLUME_ONLY if is_given(args, name)
                 and not (cluster_render and name in ("workers", "scheduler"))
                 and not ((rgba or post) and name in TF_OPTIONS)]  # a scalar .clw: classified while rendering
        if given:
            them = 'them' if len(given) > 1 else 'it'
            if set(given) <= {flag(name) for name in TF_OPTIONS} and getattr(args, "xray", False):
                raise InputError(f"{', '.join(given)} {'classify' if len(given) > 1 else 'classifies'} a scalar .clw "
                                 f"for shaded ray tracing; --xray draws the line integrals of the model as it is: "
                                 f"leave {them} or --xray out")
            if set(given) <= {flag(name) for name in TF_OPTIONS} and hasattr(args, "xray") and args.method == "splat":
                # render and progressive: a scalar .clw takes them while ray tracing
                verb = 'classify' if len(given) > 1 else 'classifies'
                raise InputError(f"{', '.join(given)} {verb} a scalar .clw while ray tracing: add --method raytrace "
                                 f"(splatting draws line integrals of the model as it is), or compress the original "
                                 f"volume with {them}")
            raise InputError(f"{', '.join(given)} cannot apply to {args.input}: a .clw file is a wavelet model "
                             f"already; compress the original volume with {them}")
        if opener is not None and args.threshold is None and args.noise is None and args.focus is None:
            return opener(args.input, args.keep), None
        wv = WaveletVolume.open(args.input, keep=args.keep if args.focus is None and args.noise is None else None)
        if rgba and wv.photo:
            raise InputError(f"shaded ray tracing needs a classified model; {args.input} holds a photo's colour and "
                             f"alpha: compress the original volume with --tf photo (opacity its alpha) or another "
                             f"--tf PRESET, or render line integrals with --xray")
        if rgba and wv.channels != 4 and post_transfer_function(args, wv) is None:
            raise _needs_rgba(args.input, wv.channels, "give --tf PRESET to classify it while rendering, or "
                                                       "compress the volume with --tf PRESET" if wv.channels == 1 else
                              "compress the original volume with --tf PRESET (its colours kept, the preset's "
                              "opacity of their luminance)")
        if args.threshold is not None or args.noise is not None or args.focus is not None:  # --keep alone: a prefix
            wv = wv.threshold(**thresholding)
            warn_stored(wv, args.keep, args.input)  # as WaveletVolume.open(keep=) tells it
        return wv, None
    if getattr(args, "tf", None) and args.noise is not None and args.classify == "pre":  # RGBA noise is not the values'
        raise InputError(f"--noise measures the noise of {args.input}'s values, and --tf classifies them first "
                         f"(--classify pre): give --classify post, which keeps the values to threshold and classifies "
                         f"them while ray tracing (docs/model.md §2)")
    vol = read_volume(args) if volume is None else volume
    tf = preset_transfer_function(args)
    if tf is None and vol.photo and vol.channels == 4:  # straight colour and alpha, as the best tools read it
        args.tf, tf = "photo", TransferFunction.preset("photo")  # as if given: so reported, and copied by the viewer
        log(f"{args.input}: a photo's colour and alpha, classified by its alpha (--tf photo; --tf PRESET for another)")
    hinted = hu_hint and not (tf or args.subtract or getattr(args, "hu_to_mu", False))
    least = air_in_hounsfield(vol.data) if hinted else None
    if least is not None:  # padding below air stays negative with --subtract -1000; --hu-to-mu clips it to air
        padding = (f", and padding down to {least:.6g} that --subtract -1000 leaves negative (an X-ray integrates it): "
                   f"give --hu-to-mu (padding to 0 with air)" if least < -1100 else
                   ": give --subtract -1000 (air to 0) or --hu-to-mu")
        warn(f"{args.input} looks like CT in Hounsfield units (most border voxels air, -1000, or padding below it); "
             f"the model spends its coefficients on that constant{padding}")
    post = tf is not None and args.classify == "post"
    if post and vol.channels != 1:
        raise InputError(f"--classify post keeps a scalar volume for ray tracing to classify; {args.input} has "
                         f"{vol.channels} channels: leave --classify post out")
    if rgba and tf is None and vol.channels != 4:
        presets = ", ".join(TransferFunction.PRESETS)
        raise _needs_rgba(args.input, vol.channels, f"classify it with --tf PRESET ({presets})")
    wavelet = args.wavelet or DEFAULT_WAVELET
    wavelet = wavelet.split(",") if "," in wavelet else wavelet
    levels = args.levels
    if levels is None:  # a thin volume's shortest axis caps them: said, with what --keep then does
        levels, note = default_levels(vol.shape, thresholded=args.keep != 1)
        if note:
            warn(note)
    wavelet, levels = check_decomposition(vol.shape, 4 if tf and not post else vol.channels, wavelet, levels)
    if vol.chunked and args.interpolate:
        raise InputError("--interpolate needs the whole volume in memory (its prefilter is global); leave it out "
                         "for a chunked input, or read the input whole with --chunks off")
    if tf is not None:
        tf = tf.resolved(vol)  # records an "auto" window
        vol = vol if post else _classified(args, tf, vol)  # post: the scalar, and tf as its default for ray tracing
        if post and not vol.chunked:  # refused now, as classifying first would, not by the first render of the file
            _classified(args, tf, vol, check=True)
    start = time.perf_counter()
    wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels, interpolate=args.interpolate,
                                   transfer_function=tf, scheduler=scheduler)
    log(f"{'read (content) of' if vol.chunked else 'decomposed'} {' x '.join(map(str, vol.shape[::-1]))} voxels "
        f"(x, y, z), {vol.channels} channel(s), in {time.perf_counter() - start:.2f} s")
    if tf is not None and not post and vol.chunked and wv.content is None:  # classified as read: its content pass
        from ..errors import NothingVisibleError                            # found no voxel with any opacity
        why = (f"the transfer function{f' {tf.name}' if tf.name else ''} gives no voxel of this volume (read chunk by "
               f"chunk) any opacity; give a window in the input's units (--tf-window LO,HI) or another preset")
        raise NothingVisibleError(why + (" (--hu-to-mu turned HU into attenuation per mm)" if args.hu_to_mu else ""))
    if noise and not vol.chunked:  # before thresholding (a partial sort): compress records it and reports by it
        wv.measure_noise()
    default = args.keep is None and args.threshold is None and args.noise is None
    with warnings.catch_warnings():  # a budget below the approximation band is told where --keep or --focus chose it
        if default and args.focus is None:
            warnings.simplefilter("ignore", ClwaveWarning)
            warnings.simplefilter("always", NoisyModelWarning)  # a default model of noise is told
        wv = wv.threshold(**dict(thresholding, keep=DEFAULT_KEEP) if default else thresholding)
    if not vol.chunked:
        return wv, vol
    return (wv.compute() if gather else wv), None


def _classified(args, tf, vol, check=False):
    """``vol`` classified by ``tf`` (``check``: only checked, a scalar kept to classify while rendering); a
    classification without opacity anywhere is refused before the transform, where --hu-to-mu is the likely cause (a
    HU preset on attenuation) saying so."""
    from ..errors import NothingVisibleError

    try:
        return tf.check_visible(vol) if check else tf.classify(vol)
    except NothingVisibleError as exc:
        if not args.hu_to_mu:
            raise
        raise NothingVisibleError(str(exc), cli=f"{exc.cli_message()} (--hu-to-mu turned HU into attenuation per "
                                                f"mm)") from None


def preset_transfer_function(args):
    """The transfer function of ``--tf PRESET|FILE [--tf-window auto|LO,HI] [--opacity-unit LENGTH] [--key
    R,G,B[,TOL]|auto]``, or None without ``--tf``."""
    from ..model.colour_key import check_key
    from ..model.tf_file import named_transfer_function

    if not getattr(args, "tf", None):  # drr has no --tf
        for name, what in (("tf_window", "window"), ("opacity_unit", "opacity unit"), ("key", "colour key")):
            if getattr(args, name, None) is not None:
                raise InputError(f"{flag(name)} sets the {what} of a --tf preset: give --tf too")
        return None
    tf = named_transfer_function(args.tf, None if args.tf_window is None else parse_tf_window(args.tf_window))
    key = getattr(args, "key", None)  # view's and compress's, render's, progressive's
    return _with_unit(args, tf if key is None else tf.under(key=check_key(key, "--key")))


def _with_unit(args, tf):
    """``tf`` with ``--opacity-unit``'s length where given."""
    return tf if args.opacity_unit is None else tf.under(opacity_unit=args.opacity_unit)


def post_transfer_function(args, wv):
    """The transfer function that classifies a scalar model while ray tracing (docs/raytracing.md §10): on a .clw
    input ``--tf`` (with ``--tf-window``), else the model's own (``--tf PRESET --classify post``; a .clw input's
    with ``--tf-window`` if given); None for a classified model or a scalar one without any."""
    from ..model.transfer import TransferFunction

    clw = is_clw(args)
    if wv.channels != 1:
        if clw and (args.tf or args.tf_window or args.opacity_unit) and wv.channels == 4:
            raise InputError(f"--tf and --tf-window classify a scalar model; {args.input} has 4 channels (classified "
                             "already): leave them out")
        if clw and (args.tf or args.tf_window or args.opacity_unit):
            raise InputError(f"--tf and --tf-window classify a scalar model; {args.input} is a {wv.channels}-channel "
                             "model, which they do not classify and shaded ray tracing cannot draw: render its line "
                             "integrals with --xray or --method splat, or compress the original volume with --tf "
                             "PRESET")
        return None
    if clw and (args.tf or wv.transfer_function is None):
        return preset_transfer_function(args)
    tf = None if wv.transfer_function is None else TransferFunction.from_dict(wv.transfer_function)
    if tf is not None and clw and args.tf_window is not None:
        tf = tf.under(parse_tf_window(args.tf_window))
    return tf if tf is None else _with_unit(args, tf)


def parse_tf_window(text):
    """``--tf-window``'s "auto", or its two numbers (checked by :func:`~clwave.model.transfer.check_window`)."""
    return text if text == "auto" else numbers(text, "--tf-window", (2,))


def check_outputs(force, *outputs) -> list:
    """The paths of a command's outputs ``(path or None, option, suffixes[, hint])``, each checked before any work:
    it ends in one of ``suffixes`` (else refused with ``hint``, the option that writes other files), its folder
    exists and takes a new file, it is no folder, it exists only with ``--force``; and no two name one file.  None
    where an output is not asked for."""
    paths, seen = [], {}
    for path, opt, suffixes, *hint in outputs:
        if path is None:
            paths.append(None)
            continue
        if not str(path):  # Path("") is "."
            raise InputError(f"{opt} '' names no file; name one")
        if str(path).endswith(("/", os.sep)):  # Path() drops it: "a.png/" would write a.png
            raise InputError(f"{opt} {path} ends in a slash, naming a folder; name a file")
        path = Path(path)
        if path.suffix.lower() not in suffixes:
            raise InputError(f"{opt} {path} must end in {' or '.join(suffixes)}{''.join('; ' + h for h in hint)}")
        if path.is_dir():
            raise InputError(f"{opt} {path} is a folder; name a file")
        if not path.parent.is_dir():
            raise InputError(f"the folder of {opt} {path} does not exist; create it first")
        check_writable(path)
        if path.exists() and not force:
            raise OutputExistsError(f"{path} exists; pass --force to replace it")
        same = seen.get(os.path.realpath(path))  # one file by two names, links included
        if same is not None:
            raise InputError(f"{same} and {opt} both name {path}; give each output its own file")
        seen[os.path.realpath(path)] = opt
        paths.append(path)
    return paths


def finish(outputs, lines):
    """A command's last step: its ``outputs`` (:func:`~clwave.io.files.published_together`) published together, then
    its report on stdout, which names only what is in place: exit 0 with the outputs published even where stdout takes
    nothing (a full disk: a warning; a reader that left, ``| head -1``: quietly, as it chose) (coordinates.md §4)."""
    outputs.publish()
    try:
        for line in lines:
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()
    except OSError as exc:  # the OutputError of the command line's checked stdout too
        silence_stdout()
        why = str(exc) if isinstance(exc, OutputError) else f"cannot write to standard output: {exc.strerror or exc}"
        warn(f"{why}; the outputs are published, the report lost")


def silence_stdout():
    """Point stdout's file descriptor at /dev/null (where it has one), so that the interpreter's last flush of what
    stdout could not take fails no more (its exit code would be 120)."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # a stdout with no file descriptor (a test's capture), or none
        pass


def check_frames_output(path, force) -> Path:
    """``-o`` of progressive frames: a .gif (checked with the other outputs), or a folder for PNG frames: none yet, or
    an empty one (any with ``--force``), never a file."""
    if not str(path):  # Path("") is ".": the frames were written into the current folder
        raise InputError("-o '' names no folder; name one for the PNG frames, or a .gif")
    path = Path(path)
    if path.suffix:
        if path.suffix.lower() != ".gif":
            raise InputError(f"output {path} must end in .gif, or be a folder name for PNG frames")
        return path
    if path.exists() and not path.is_dir():
        raise InputError(f"-o {path} is a file; name a folder for the PNG frames, or a .gif")
    if path.is_dir() and any(path.iterdir()) and not force:
        raise InputError(f"folder {path} is not empty; pass --force to write into it")
    return path


def add_camera_options(p):
    from ..model.camera import FITS
    from ..model.geometry import VIEWS

    g = p.add_argument_group("view")
    g.add_argument("--azimuth", type=float, help="degrees (default 30; with neither angle nor --view, a slab opens "
                                                 "showing its face: docs/coordinates.md §2)")
    g.add_argument("--elevation", type=float, help="degrees (default 20; a slab: its face)")
    g.add_argument("--view", choices=VIEWS, help="a RAS volume's side, drawn as radiographs are: anterior (AP: the "
                   "patient's left on the image's right), posterior, left, right (laterals), inferior (as CT slices), "
                   "superior; instead of --azimuth and --elevation")
    g.add_argument("--perspective", action="store_true", help="perspective camera (default orthographic)")
    g.add_argument("--fov", type=float, help="with --perspective: vertical field of view, degrees (default 30)")
    g.add_argument("--distance", type=float, help="with --perspective: eye distance from the target (world units; "
                   "default twice the framed width, --extent or --fit's; with --fit box the least that keeps the "
                   "content's box in view)")
    g.add_argument("--size", default="512", help="image size: N or HxW, e.g. 512 or 300x400 (default 512)")
    g.add_argument("--extent", type=float, help="world width of the image (default: by --fit)")
    g.add_argument("--fit", choices=FITS, default="sphere", help="default framing: sphere (the bounding sphere of "
                   "the non-empty voxels spans the image, the same at every view) or box (their box's projection "
                   "for this view fills the image: an elongated volume seen from its side)")
    g.add_argument("--scale-bar", nargs="?", const=True, type=float, metavar="LENGTH",
                   help="PNG and GIF: burn in a scale bar of LENGTH world units, labelled in the input's unit (without "
                        "LENGTH 1, 2 or 5 times a power of ten, about a fifth of the width); orthographic only")
    add_device_options(g)


def add_device_options(g):
    """The display window and the device options of every rendering command (``g``: an argument group)."""
    g.add_argument("--window", dest="display_window", default="auto",
                   help="PNG window: auto (the default: from the image's values) or LO,HI")
    g.add_argument("--colour-map", "--colormap", metavar="NAME",
                   help="PNG and GIF of a one-channel X-ray: its grey levels in a colour map, grey (the default), "
                        "bone, viridis, inferno, magma, or the diverging seismic, RdBu or coolwarm (their auto window "
                        "centred on 0 for signed values), or one of them reversed, NAME_r: grey_r shows dark bright "
                        "(dark protein as 3dmod's inverse contrast, napari's gray_r)")
    g.add_argument("--colour-bar", "--colorbar", action="store_true",
                   help="PNG and GIF of a one-channel X-ray: burn in a colour bar, the map's colours from the window's "
                        "low end to its high end, labelled with both and 0 between them (top right)")
    g.add_argument("--bit-depth", type=int, choices=(8, 16), help="PNG: bits a sample, 8 (the default) or 16")
    g.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    g.add_argument("--omega-s", type=float, help="footprint band (paper eq. 35; default from the pixel size)")
    g.add_argument("--coarse", type=float, help="splatting: draw coarse cubic and quintic bands into coarser "
                   "framebuffers within this error relative to the image maximum, and in perspective drop splats "
                   "within what is left of it (e.g. 1e-2; 0: off; default: off, but 1e-3 where render writes "
                   "8-bit pictures only, through the automatic window: no --raw, .tif, --bit-depth 16 or "
                   "--window LO,HI)")
    g.add_argument("--device-memory", metavar="SIZE", help="device memory to use at most, e.g. 2GiB or 512M "
                   "(default: the device's); splatting streams coefficients beyond it in chunks (docs/splatting.md "
                   "§6), ray tracing renders bricks beyond it in passes (docs/raytracing.md §6)")


def add_raytrace_options(p):
    g = p.add_argument_group("ray tracing (--method raytrace)")
    g.add_argument("--tolerance", type=float, help="absolute error per output value (default 1e-3)")
    g.add_argument("--light", action="append", help="directional light AZ,EL in degrees; repeat for more; "
                   "'none' for ambient only (default: a headlight)")
    g.add_argument("--no-shading", action="store_true", help="unlit emission")
    g.add_argument("--xray", action="store_true", help="line integrals without absorption, as splatting")
    g.add_argument("--clip-box", metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="keep only what lies in this box, world coordinates (docs/coordinates.md §6)")
    g.add_argument("--clip-voxels", metavar="Z0:Z1,Y0:Y1,X0:X1",
                   help="keep only these voxels of the input array, indices in its axis order as clwave info prints "
                        "its shape (before --orientation turns it), Z1 excluded, an end left out the array's "
                        "(e.g. 300:400,50:100,:); instead of --clip-box")
    g.add_argument("--clip-plane", action="append", metavar="PX,PY,PZ,NX,NY,NZ",
                   help="keep only the side of the plane through point P that its normal N points to; repeatable")
    g.add_argument("--background", help="PNG: colour R,G,B behind the volume, linear RGB in 0..1, composited before "
                                        "the sRGB encoding (0.5 is shown as 188; default 0,0,0, black), or "
                                        "transparent (RGBA)")
    g.add_argument("--field", choices=("bspline", "wavelet"),
                   help="evaluate the field from fine B-spline grids (fast, the default) or from the wavelet "
                        "coefficients with per-ray active lists (the paper's reference, of the model without the "
                        "content clamp: docs/raytracing.md §4)")


def parse_device_memory(args):
    """``device_memory=`` from ``--device-memory SIZE``, checked before any work."""
    from ..device.memory import parse_cap

    return parse_cap(args.device_memory)


def add_command(sub, name, help, run, output_help, view=False, classify=True):
    """A subcommand reading a volume into a wavelet model and writing ``-o`` (``--force`` to replace); ``classify``:
    with the transfer function's options (:func:`add_model_options`)."""
    p = sub.add_parser(name, help=help)
    add_input_options(p)
    add_model_options(p, classify)
    if view:  # a perspective camera's fixes, in this command's options (errors.CommandWords)
        add_camera_options(p)
        p.set_defaults(words=CommandWords("--fov or --size", "--distance", f"clwave {name} --method raytrace --xray"))
    p.add_argument("-o", "--output", required=True, help=output_help)
    p.add_argument("--force", action="store_true", help="replace existing output files")
    p.set_defaults(run=run)
    return p


def kept_words(kept, voxels) -> str:
    """``kept`` coefficients and their share of a model's ``voxels``, as the commands report them."""
    return f"{kept:,} coefficients ({100 * kept / voxels:.2f} % of the voxels)"


def error_words(error) -> str:
    """A model's RMS error over the voxels relative to its input's largest |value| (a .clw's ``model_error``), as
    the commands report it."""
    return f"RMS over the voxels {error:.2e} of the largest value (PSNR {-20 * math.log10(max(error, 1e-30)):.1f} dB)"


def file_size(n) -> str:
    """A file's size in decimal units, as the commands report it ("13.1 KB")."""
    for unit in ("bytes", "KB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:,.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
