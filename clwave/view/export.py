"""A tab's view as the command line and the Python that render it, and as an image at a chosen size (docs/viewer.md
§5): the one home of the translation from the viewer's state to ``clwave render``'s options and to ``clwave.splat`` /
``clwave.raytrace``'s arguments; the page only shows and copies the text.

A view is first resolved (:func:`resolve`, on the render thread: a scalar model's transfer function needs the tracer's
pool for an "auto" window) into a :class:`Spec` whose every figure is explicit (the camera's extent, the X-ray window,
the transfer function's window), so that the command renders what the server renders, not what the command's own
defaults would choose.  :func:`picture` renders a spec with the renderers the command line calls (``splat`` with the
viewer's :class:`~clwave.SplatRenderer`, the viewer's :class:`~clwave.RayTracer`'s ``render``), at full quality.
"""

from __future__ import annotations

import json
import os
import shlex
from dataclasses import dataclass
from functools import partial

from ..errors import ClwaveError, InputError
from ..model.camera import Camera
from ..model.clip import Clip
from ..model.transfer import TransferFunction
from . import colours
from .protocol import said

#: the files the command and the Python write
OUTPUT, TF_FILE = "view.png", "view-tf.json"
#: host bytes a pixel of a saved image may take at the least (the viewer's own floor, docs/viewer.md §1): a size whose
#: image would outgrow the memory available now is refused before it is rendered
SAVE_PIXEL_BYTES = 200
#: the header of a saved image's response that holds, as a JSON string, the renderer's warnings of it (the page's note)
NOTE_HEADER = "X-Clwave-Note"
#: the model options that make its transfer function: a scalar model's shaded view replaces them with the tab's (its
#: opacity unit in the tab's function)
TF_OPTIONS = ("tf", "tf_window", "opacity_unit")
#: the reading options that clwave.load takes by the same name
LOAD_OPTIONS = ("shape", "dtype", "byte_order", "spacing", "series", "subtract", "hu_to_mu", "nan", "level", "frame",
                "orientation", "unit", "labels")


@dataclass(frozen=True)
class Origin:
    """How the served model was made: the ``input`` as given to ``clwave view`` (None: a model given to
    ``clwave.view()`` in Python, which no command reads) and the reading and model ``options`` given, as
    ``(dest, flag, value)`` (a switch's value True, or False for ``--no-labels``)."""

    input: str | None = None
    options: tuple = ()

    @classmethod
    def of_args(cls, args) -> "Origin":
        """The input and the reading and model options of a ``clwave view`` command line that differ from their
        defaults (the same options as ``render``'s: one parser makes both, cli/options.py and
        cli/reading.py)."""
        import argparse

        from ..cli.options import add_model_options
        from ..cli.reading import add_input_options

        parser = argparse.ArgumentParser(add_help=False)
        add_input_options(parser)
        add_model_options(parser)
        given = []
        for action in parser._actions:
            value = getattr(args, action.dest, action.default)
            if isinstance(action, argparse._StoreConstAction):  # a switch: --hu-to-mu, --labels, --no-labels
                if value is action.const and value is not action.default:
                    given.append((action.dest, action.option_strings[-1], value))
            # "is not False", for 0 == False: an option given as 0 (--threshold 0, --nan 0) is given
            elif action.option_strings and value is not None and value is not False and value != action.default:
                given.append((action.dest, action.option_strings[-1], value))
        return cls(args.input, tuple(given))

    def get(self, dest):
        return next((value for d, _, value in self.options if d == dest), None)


@dataclass(frozen=True)
class Spec:
    """A view with every figure explicit: ``window`` the X-ray picture's, ``tf`` a scalar model's shaded one (its
    window in numbers), ``colour_map`` None for an RGBA model's X-ray."""

    mode: str
    camera: Camera
    window: tuple | None = None
    colour_map: str | None = None
    detail: float = 1.0
    tolerance: float | None = None
    shading: bool = True
    background: float = 0.0
    tf: TransferFunction | None = None
    scale_bar: bool = False  # the default --scale-bar (an orthographic view's)
    clip: Clip | None = None  # a shaded view's (an X-ray is splatted: never clipped)
    levels: int = 0  # the model's (the Python of a volume decomposes it with as many)


def resolve(sources: dict, state, size=None) -> Spec:
    """The :class:`Spec` of a tab's ``state`` at ``size`` (H, W; None: the page's), on the render thread."""
    from ..io.images import check_orthographic

    source = sources[state.mode]
    camera = source.camera(state, size=size)
    levels, scale_bar = source.wv.levels, state.scale_bar
    if scale_bar:
        check_orthographic(camera.to_dict())
    if state.mode == "xray":
        return Spec("xray", camera, tuple(state.window or colours.centred(source.auto_window, state.colour_map)),
                    state.colour_map if source.capabilities["colour_map"] else None, state.detail, scale_bar=scale_bar,
                    levels=levels)
    source.start_full_stage()
    if source.tracer is None:
        failure = None if source.staged is None else source.staged.failure
        if failure is not None:
            raise Failed(f"the shaded views' ray tracer of the whole file could not be made ({said(failure)}): they "
                         f"show the file's coarse stage, which no saved image or command draws")
        raise Unavailable("the shaded views' ray tracer is still being made (or the whole file read): try again once "
                          "the view has been refined")
    tf, window = source.transfer_function(state.tf, source.tracer)
    if tf is not None and tf.window == "auto":  # the pool's percentiles, written as numbers
        tf = tf.under(window=tuple(window))
    return Spec("shaded", camera, tolerance=source.tolerance, shading=state.shading, background=state.background,
                tf=tf, scale_bar=scale_bar, levels=levels, clip=state.clipping())


class Unavailable(InputError):
    """What a view needs is not there yet (its tracer, a file's rest): asked again later, it is."""


class Failed(ClwaveError):
    """What a view needs could not be made (a file's full stage): asked again, it will not be."""


def picture(sources: dict, spec: Spec):
    """The picture of ``spec`` at full quality (every kept coefficient; the tracer's full detail at its tolerance), by
    the renderers ``clwave render`` calls, as a generator of the render thread's stages that returns its PNG's pixels
    (an X-ray in the tab's colour map; a scale bar over it): splatted or traced in turns (``splat_in_turns``,
    ``RayTracer.rendering``: the tabs' frames go between two of its stages, docs/viewer.md §5)."""
    from ..io.images import draw_scale_bar
    from ..splat.renderer import splat_in_turns
    from ..threads import in_turns

    source = sources[spec.mode]
    if spec.mode == "xray":
        if spec.detail < 1.0:
            raise InputError(f"detail kept {100 * spec.detail:.3g} %: a saved image has every kept coefficient, as "
                             f"clwave render draws them; set detail kept to 100 %")
        if not source.complete:
            raise Unavailable("the rest of the file is still being read: save once the model line says it is in")
        result = yield from splat_in_turns(source.r, spec.camera)
        image = result.to_uint8(spec.window)
        image = colours.apply(image, spec.colour_map) if spec.colour_map else image
    else:
        tracer = source.tracer
        result = yield from in_turns(tracer.lock, tracer.rendering(
            spec.camera, tolerance=spec.tolerance, shading=spec.shading, clip=spec.clip,
            **({} if spec.tf is None else dict(transfer_function=spec.tf))))
        image = result.to_uint8(background=(spec.background,) * 3)
    return draw_scale_bar(image, result.meta["pixel"], source.wv.unit) if spec.scale_bar else image


def check_save_size(size):
    """Refuse, before rendering, a saved image whose pixels would outgrow the host memory available now."""
    from ..device.memory import check_fits

    H, W = size
    check_fits(H * W * SAVE_PIXEL_BYTES, f"saving a {H}x{W} image", "choose a smaller size")


# ---------------------------------------------------------------------------------------------------- the command
def _number(x) -> str:
    return repr(float(x))


def _token(flag, value) -> list:
    """``[flag, value]``, or ``[flag=value]`` where the value begins with "-" (argparse would take it for an option)."""
    value = value if isinstance(value, str) else _number(value) if isinstance(value, float) else str(value)
    return [f"{flag}={value}"] if value.startswith("-") else [flag, value]


def _is_preset(tf: TransferFunction) -> bool:
    """Whether ``tf`` is a preset under a window of numbers (``--tf NAME --tf-window LO,HI`` says it)."""
    return (tf.name in TransferFunction.PRESETS and isinstance(tf.window, tuple)
            and tf == TransferFunction.preset(tf.name, window=tf.window))


def command(origin: Origin, spec: Spec, output=OUTPUT) -> str:
    """The shell lines that render ``spec`` with ``clwave render``: a ``.json`` of the transfer function first where
    no preset names it; lines beginning ``#`` say what of the view no option sets."""
    if origin.input is None:
        return ("# the model was given to clwave.view() in Python: no command line reads it; the Python renders this "
                "view of it")
    clw = origin.input.lower().endswith(".clw")
    scalar_tf = spec.mode == "shaded" and spec.tf is not None
    # an input whose name begins with "-" (a relative path: an absolute one begins with "/") is not an option
    source = f"./{origin.input}" if origin.input.startswith("-") else origin.input
    before, tokens, notes = [], ["clwave", "render", source], []
    for dest, flag, value in origin.options:
        # a scalar model's shaded view: the tab's function in place of the one given; an X-ray of a .clw: none
        if dest in TF_OPTIONS and (scalar_tf or clw):
            continue
        tokens += [flag] if isinstance(value, bool) else _token(flag, value)
    tokens += ["--method", "splat" if spec.mode == "xray" else "raytrace"]
    if scalar_tf:
        if _is_preset(spec.tf):
            tokens += ["--tf", spec.tf.name, *_token("--tf-window", ",".join(map(_number, spec.tf.window)))]
        else:
            before = [f"cat > {TF_FILE} <<'EOF'", json.dumps(spec.tf.to_dict()), "EOF"]
            tokens += ["--tf", TF_FILE]
        if not clw and origin.get("classify") != "post":  # a volume: kept scalar, classified while rendering
            tokens += ["--classify", "post"]
    cam = spec.camera
    tokens += [*_token("--azimuth", cam.azimuth), *_token("--elevation", cam.elevation)]
    if cam.perspective:
        tokens += ["--perspective", "--fov", _number(cam.fov), "--distance", _number(cam.distance)]
    else:
        tokens += ["--extent", _number(cam.extent)]
    tokens += ["--size", f"{cam.size[0]}x{cam.size[1]}"]
    if spec.mode == "xray":
        tokens += _token("--window", ",".join(map(_number, spec.window)))
        tokens += [] if spec.colour_map in (None, "grey") else ["--colour-map", spec.colour_map]
        if spec.detail < 1.0:
            notes.append(f"# not in this command: detail kept {100 * spec.detail:.3g} % (clwave render splats every "
                         f"kept coefficient)")
    else:
        tokens += ["--tolerance", _number(spec.tolerance)]
        tokens += [] if spec.shading else ["--no-shading"]
        if spec.background:
            tokens += ["--background", ",".join([_number(spec.background)] * 3)]
        if spec.clip is not None:
            if spec.clip.lo is not None:
                tokens += _token("--clip-box", ",".join(map(_number, (*spec.clip.lo, *spec.clip.hi))))
            for point, normal in spec.clip.planes:
                tokens += _token("--clip-plane", ",".join(map(_number, (*point, *normal))))
    tokens += ["--scale-bar"] if spec.scale_bar else []
    tokens += ["-o", output]
    return "\n".join(notes + before + [" ".join(map(_shell_word, tokens))])


def _shell_word(text: str) -> str:
    """``text`` as one shell word: ``shlex.quote``, or where it is no UTF-8 (a file name that is not, surrogate-escaped
    by Python, which a page's text would carry as U+FFFD) bash's ``$'\\xHH...'`` of its bytes."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return "$'" + "".join(f"\\x{byte:02x}" for byte in os.fsencode(text)) + "'"
    return shlex.quote(text)


# ---------------------------------------------------------------------------------------------------- the Python
def python(origin: Origin, spec: Spec, output=OUTPUT) -> str:
    """Python that renders ``spec``: the model read as ``clwave view`` read it, the camera, ``clwave.splat`` or
    ``clwave.raytrace`` with the view's arguments, and the picture saved."""
    lines = ["import clwave", ""] + _model(origin, spec)
    cam, bar = spec.camera, ", scale_bar=True" if spec.scale_bar else ""
    framing = f"perspective=True, fov={_number(cam.fov)}, distance={_number(cam.distance)}" if cam.perspective \
        else f"extent={_number(cam.extent)}"
    lines.append(f"camera = clwave.Camera(azimuth={_number(cam.azimuth)}, elevation={_number(cam.elevation)}, "
                 f"size={tuple(cam.size)!r}, {framing})")
    if spec.mode == "xray":
        if spec.detail < 1.0:
            lines.append(f"# not in this snippet: detail kept {100 * spec.detail:.3g} % (every kept coefficient)")
        lines += ["result = clwave.splat(wv, camera)",
                  f"result.save({output!r}, window=({_number(spec.window[0])}, {_number(spec.window[1])}){bar}"
                  f"{'' if spec.colour_map in (None, 'grey') else f', colour_map={spec.colour_map!r}'})"]
        return "\n".join(lines) + "\n"
    options = f", tolerance={_number(spec.tolerance)}"
    if spec.tf is not None:
        lines.append(f"tf = clwave.TransferFunction.preset({spec.tf.name!r}, window={spec.tf.window!r})"
                     if _is_preset(spec.tf) else f"tf = clwave.TransferFunction.from_dict({spec.tf.to_dict()!r})")
        options += ", transfer_function=tf"
    options += "" if spec.shading else ", shading=False"
    if spec.clip is not None:
        box = "" if spec.clip.lo is None else f"lo={_numbers(spec.clip.lo)}, hi={_numbers(spec.clip.hi)}, "
        planes = ", ".join(f"({_numbers(p)}, {_numbers(n)})" for p, n in spec.clip.planes)
        lines.append(f"clip = clwave.Clip({box}planes=[{planes}])")
        options += ", clip=clip"
    lines.append(f"result = clwave.raytrace(wv, camera{options})")
    background = f", background={(spec.background,) * 3!r}" if spec.background else ""
    lines.append(f"result.save({output!r}{background}{bar})")
    return "\n".join(lines) + "\n"


def _numbers(values) -> str:
    return f"({', '.join(map(_number, values))})"


def _model(origin: Origin, spec: Spec) -> list:
    """The lines that make ``wv`` as ``clwave view`` made it (a ``.clw`` file opened; a volume read, classified where
    it was, decomposed with the served model's levels and thresholded); a line naming the options they leave out."""
    if origin.input is None:
        return ["# wv: the model given to clwave.view()"]
    given = {dest for dest, _, _ in origin.options}
    if origin.input.lower().endswith(".clw"):
        keep, rule = origin.get("keep"), _rule(origin)
        lines = [f"wv = clwave.WaveletVolume.open({origin.input!r}{'' if keep is None else f', keep={keep!r}'})"]
        lines += [] if rule is None else [f"wv = wv.threshold({rule})"]
        left = given - {"keep", "threshold", "noise", *TF_OPTIONS}
    else:
        lines, left = _volume(origin, spec)
    if left:
        flags = ", ".join(flag for dest, flag, _ in origin.options if dest in left)
        lines.insert(0, f"# not in this snippet: {flags} (given to clwave view; the command line has them)")
    return lines


def _volume(origin: Origin, spec: Spec) -> tuple:
    """A volume input's lines, and the options they leave out."""
    given = {dest for dest, _, _ in origin.options}
    if origin.input.startswith("phantom:"):
        name, _, n = origin.input[len("phantom:"):].partition(":")
        lines = [f"vol = clwave.phantom({name!r}, n={int(n or 128)})"]
        left = given & {"spacing", "subtract"}
    else:
        read = "".join(f", {dest}={_load_value(dest, origin.get(dest))!r}" for dest in LOAD_OPTIONS if dest in given)
        lines, left = [f"vol = clwave.load({origin.input!r}{read})"], set()
    tf, post = origin.get("tf"), origin.get("classify") == "post"
    if tf is not None:
        if tf not in TransferFunction.PRESETS:
            left |= set(TF_OPTIONS)
        else:
            window, unit = origin.get("tf_window"), origin.get("opacity_unit")
            window = "" if window is None else f", window={window if window == 'auto' else _floats(window)!r}"
            unit = "" if unit is None else f", opacity_unit={unit!r}"
            lines += [f"tf = clwave.TransferFunction.preset({tf!r}{window}{unit}).resolved(vol)"]
            lines += [] if post else ["vol = tf.classify(vol)"]
    wavelet = origin.get("wavelet") or "cubic"
    wavelet = wavelet.split(",") if "," in wavelet else wavelet
    keep = origin.get("keep")
    thresholding = _rule(origin) or f"keep={0.05 if keep is None else keep!r}"
    lines.append(f"wv = clwave.WaveletVolume.from_volume(vol, wavelet={wavelet!r}, levels={spec.levels}"
                 f"{', interpolate=True' if origin.get('interpolate') else ''}"
                 f"{', transfer_function=tf' if tf in TransferFunction.PRESETS else ''}).threshold({thresholding})")
    return lines, left | (given - {*LOAD_OPTIONS, *TF_OPTIONS, "classify", "wavelet", "levels", "keep", "threshold",
                                   "noise", "interpolate"})


def _rule(origin: Origin):
    """``threshold=T`` or ``noise=K`` as given to ``clwave view`` (None: neither)."""
    for name in ("threshold", "noise"):
        if origin.get(name) is not None:
            return f"{name}={origin.get(name)!r}"
    return None


def _floats(text) -> tuple:
    return tuple(float(v) for v in str(text).split(","))


def _load_value(dest, value):
    """A reading option's value as ``clwave.load`` takes it (the command line's text parsed as its parser does)."""
    if dest == "shape":
        return tuple(int(v) for v in value.split(","))
    if dest == "spacing":
        spacing = _floats(value)
        return spacing[0] if len(spacing) == 1 else spacing
    if dest == "series" and str(value).isdigit():
        return int(value)
    return value


# ---------------------------------------------------------------------------------------------------- the routes
async def stage_by_stage(loop, server, stages, notes):
    """What the generator ``stages`` returns, each of its stages a job of its own on the ``server``'s render thread
    (its warnings logged and added to ``notes``, ``server.logged``), so that the jobs queued meanwhile (the tabs'
    frames) go between two."""
    def step():
        try:
            next(stages)
        except StopIteration as end:  # raised into a Future, it could not be told from the others
            return True, end.value
        return False, None

    while True:
        done, value = await loop.run_in_executor(server.pool, partial(server.logged, step, notes=notes))
        if done:
            return value


async def serve(server, request, *, image: bool):
    """``POST /export`` (``image`` False: the command and the Python, JSON) or ``POST /image`` (the PNG, one at a time)
    of a page's ``{"view", "size"}`` (:func:`~clwave.view.protocol.parse_export`), worked out on the render thread
    between two stages; a request refused is one line of text (400, 409 while what it needs is made,
    507 too large for memory, 429 a save under way).  The renderer's warnings of a saved image (a frame's note, for
    the same view) come with it, JSON in the header :data:`NOTE_HEADER` (HTTP's headers are Latin-1: JSON's escapes
    keep any line's characters)."""
    import asyncio
    import contextlib

    from aiohttp import web

    from ..device.memory import HostMemoryError
    from ..errors import ClwaveError, DeviceMemoryError
    from .frames import encode
    from .protocol import Refused, parse_export

    server.check_origin(request)
    try:
        # JSON is UTF-8 (RFC 8259), whatever charset the request names: request.text() decodes by that name, and
        # raised (500, a traceback logged) for bytes that are not in it or a charset Python does not know
        state, size = parse_export((await request.read()).decode("utf-8", "replace"), tuple(server.sources))
    except Refused as exc:
        raise web.HTTPBadRequest(text=f"{exc}\n") from None

    def work():
        spec = resolve(server.sources, state, size)
        if image:
            check_save_size(size)
            return picture(server.sources, spec)
        return dict(command=command(server.origin, spec), python=python(server.origin, spec), size=list(size))

    if image and server.saving.locked():
        raise web.HTTPTooManyRequests(text="an image is being saved already: save again once it has come\n")
    loop = asyncio.get_running_loop()
    notes = []
    try:
        if state.mode == "shaded":  # its tracer made for a request before any tab's shaded view (a script's)
            building = server.prepared(server.sources["shaded"])
            if building.done() and not building.cancelled() and isinstance(building.exception(), ClwaveError):
                raise building.exception()
        async with server.saving if image else contextlib.nullcontext():
            done = await loop.run_in_executor(server.pool, partial(server.logged, work, notes=notes))
            if image:  # its stages in turn with the tabs' frames; encoded off the event loop (every tab's socket:
                done = await stage_by_stage(loop, server, done, notes)  # docs/viewer.md §5) and the render thread
                done = await loop.run_in_executor(None, partial(encode, done, lossless=True))
    except Unavailable as exc:
        raise web.HTTPConflict(text=f"{exc}\n") from None
    except Failed as exc:
        raise web.HTTPInternalServerError(text=f"{exc}\n") from None
    except (HostMemoryError, DeviceMemoryError) as exc:
        raise web.HTTPInsufficientStorage(text=f"{server.explain(exc, state.mode)}\n") from None
    except ClwaveError as exc:
        raise web.HTTPBadRequest(text=f"{exc}\n") from None
    except RuntimeError:  # the render thread's pool shut down: the server is stopping
        raise web.HTTPServiceUnavailable(text="the viewer is stopping\n") from None
    if not image:
        return web.json_response(done)
    H, W = size
    return web.Response(body=done[0], content_type="image/png",
                        headers={"Content-Disposition": f'attachment; filename="clwave-view-{H}x{W}.png"',
                                 **({NOTE_HEADER: json.dumps(" · ".join(notes))} if notes else {})})
