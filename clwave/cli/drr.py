"""``clwave drr``: digitally reconstructed radiographs, one per cone-beam pose (docs/coordinates.md §5), by
perspective splatting (docs/splatting.md §8) or the ray tracer's X-ray mode (docs/raytracing.md), streamed to one
``.npy`` stack."""

from __future__ import annotations

import csv
import time
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np

from ..errors import ClwaveError, CommandWords, InputError
from ..io.progress import progress
from .checks import check_picture_fits, parse_size, picture_options
from .options import (add_command, add_device_options, build_model, check_outputs, finish, kept_words,
                      parse_device_memory, warn)
from .reading import numbers


def read_pose_table(path) -> list:
    """The rows of a CSV pose table (a header of column names, then numbers; lines starting with ``#`` are comments)
    as dicts, the header's columns checked (:func:`~clwave.model.conebeam.matrix_columns`) before any row."""
    from ..model.conebeam import matrix_columns

    path = Path(path)
    if not path.is_file():
        raise InputError(f"pose table {path} does not exist or is not a regular file (a folder, a FIFO, a device): "
                         f"give a CSV file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:  # -sig: a spreadsheet's byte-order mark
            numbers = [n for n, line in enumerate(fh, 1) if not line.lstrip().startswith("#")]  # the file's lines
            fh.seek(0)
            reader = csv.DictReader(line for line in fh if not line.lstrip().startswith("#"))
            if reader.fieldnames:
                matrix_columns((name.strip() for name in reader.fieldnames), f"pose table {path}, header")
            rows = [_pose_row(path, numbers[reader.line_num - 1], row, len(reader.fieldnames)) for row in reader]
    except (UnicodeDecodeError, csv.Error) as e:
        raise InputError(f"pose table {path} is not a CSV text file ({e})") from None
    if not rows:
        raise InputError(f"pose table {path} has no poses (a header line of column names, then one pose a line)")
    return rows


def _pose_row(path, line, row, columns) -> dict:
    """One line of a pose table as {column: number}; an empty value takes the default of its column."""
    if None in row or None in row.values():  # more values than columns, or fewer
        values = sum(v is not None for k, v in row.items() if k is not None) + len(row.get(None, ()))
        raise InputError(f"{path}, line {line}: {values} values for the header's {columns} columns")
    try:
        return {k.strip(): float(v) for k, v in row.items() if v != ""}
    except ValueError:
        raise InputError(f"{path}, line {line}: every value must be a number") from None


def run(args):
    from ..io.files import published_together, write_atomic
    from ..io.images import TIFF_SUFFIXES, pixel_size, write_tiff
    from ..io.result import RenderResult
    from ..model.conebeam import NOT_ATTENUATION, poses, transmitted
    from ..model.signs import below_zero
    from ..model.geometry import named_view
    from ..raytrace.tracer import RayTracer
    from ..splat.renderer import SplatRenderer

    if args.signed and args.intensity:
        raise InputError("--signed writes the line integrals of values below 0 as they are; --intensity needs "
                         "attenuation (mu >= 0): leave one out")
    tolerance = args.tolerance  # checked, and its default given, with every command's (options.check_options)
    out, = check_outputs(args.force, (args.output, "-o", (".npy", ".png") + TIFF_SUFFIXES))
    look = picture_options(args, out)
    window = log_window(look["window"]) if args.intensity else look["window"]
    if args.intensity and look["colour_bar"]:
        raise InputError("--colour-bar labels line integrals; an --intensity radiograph shows intensities, on a log "
                         "scale: leave out one of them")
    H, W = parse_size(args)
    pixel, offset = numbers(args.pixel, "--pixel", (1, 2)), numbers(args.offset, "--offset", (2,))
    # in the options' words (a pose table's own columns: poses() checks them)
    if args.dso <= 0:
        raise InputError(f"--dso {args.dso:g} must be a positive source-to-isocentre distance")
    if args.dsd <= 0:
        raise InputError(f"--dsd {args.dsd:g}: the detector is behind the source; give a positive source-to-detector "
                         f"distance")
    if not (all(np.isfinite(pixel)) and min(pixel) > 0):
        raise InputError(f"--pixel {args.pixel} must be a positive detector spacing, or two (DV,DU)")
    if not all(np.isfinite(offset)):
        raise InputError(f"--offset {args.offset} must be two finite numbers A,B")
    centre = args.isocentre is None  # the volume's centre, known once it is read (docs/coordinates.md §5)
    isocentre = (0.0, 0.0, 0.0) if centre else numbers(args.isocentre, "--isocentre", (3,))
    if not all(np.isfinite(isocentre)):
        raise InputError(f"--isocentre {args.isocentre} must be three finite numbers X,Y,Z")
    if (args.poses is None) == (args.view is None):
        raise InputError("give --poses TABLE (a pose a row) or --view NAME (one pose from that side of the patient), "
                         "one of them")
    table = args.poses if args.view is None else f"--view {args.view}"
    rows = read_pose_table(args.poses) if args.view is None else [named_view(args.view)]
    geometry = dict(rows=rows, size=(H, W), pixel=pixel if len(pixel) == 2 else pixel[0],
                    dso=args.dso, dsd=args.dsd, offset=offset, isocentre=isocentre)
    cameras = table_poses(geometry, table)  # every pose checked before the input is read
    if out.suffix.lower() == ".png" and len(cameras) != 1:
        raise InputError(f"a .png holds one radiograph; {table} has {len(cameras)} poses: write .npy or .tif")
    device_memory = parse_device_memory(args)
    wv, _ = build_model(args, hu_hint=False)  # a model in HU is refused below, naming --hu-to-mu
    if wv.channels != 1:
        raise InputError(f"radiographs need a one-channel (attenuation) volume; {args.input} has {wv.channels} "
                         f"channels: give its attenuation as one channel")
    check_picture_fits(look, None, wv, xray=True)  # a --colour-map, before the render (drr has no scale bar)
    if centre:
        cameras = poses(**dict(geometry, isocentre=tuple(float(c) for c in wv.origin)))
    unit = wv.unit
    if below_zero(wv) and not args.signed:  # refused as render refuses a blank image (docs/coordinates.md §5)
        raise InputError(NOT_ATTENUATION.format(
            what=f"the model of {args.input} is", fix="read the CT with --hu-to-mu (a .clw: compress it again with "
            "--hu-to-mu)" + ("" if args.intensity else ", or give --signed for the line integrals of its values")))
    if args.method == "raytrace":  # X-ray mode: the line integrals of the same spline as splatting's, its ringing
        # beyond the content included (no content clamp, docs/raytracing.md §1)
        renderer = RayTracer(wv, device=args.device, device_memory=device_memory, content_clamp=False)

        draw = partial(renderer.render, tolerance=tolerance, absorption=False)
    else:
        renderer = SplatRenderer(wv, device=args.device, omega_s=args.omega_s, coarse=args.coarse or None,
                                 device_memory=device_memory)
        draw = renderer.render

    views = []
    for i, cb in enumerate(cameras):  # every pose's view resolved (checked) before the first is rendered
        with pose_named(table, i + 1, geometry["rows"][i]):
            views.append(cb.view(wv))

    def render(i):  # pose i's radiograph
        with pose_named(table, i + 1, geometry["rows"][i]):
            return draw(views[i])
    start = time.perf_counter()

    blank = []  # the poses (from 1) whose detector sees nothing of the model

    def image(i, res):
        if not np.any(res.image):
            blank.append(i + 1)
        return transmitted(res.image[..., 0]) if args.intensity else res.image[..., 0]

    with published_together() as outputs:  # written, then published before the report (coordinates.md §4)
        if out.suffix.lower() == ".png":
            res = render(0)
            image(0, res)
            # an intensity is shown as radiographs are: the detector's log response, bone bright (coordinates.md §5)
            picture = np.maximum(res.image, 0.0) if args.intensity else res.image
            meta = dict(res.meta, camera=cameras[0].to_dict())  # its pixel size the detector's (a view has none)
            RenderResult(picture, meta).save(out, window=window, bit_depth=look["bit_depth"],
                                             colour_map=look["colour_map"], colour_bar=look["colour_bar"],
                                             overwrite=args.force)
        else:
            stack = (len(cameras), H, W)
            poses = progress(range(len(cameras)), desc="radiographs")
            radiographs = (np.asarray(image(i, render(i)), np.float32) for i in poses)
            sizes = {pixel_size(dict(camera=cb.to_dict())) for cb in cameras}  # a TIFF's, where every pose's is one
            size = sizes.pop() if len(sizes) == 1 else None

            def write(fh):  # each radiograph as it is rendered: after the .npy header, or a TIFF page each
                if out.suffix.lower() in TIFF_SUFFIXES:
                    return write_tiff(fh, radiographs, size, unit, shape=stack)
                np.lib.format.write_array_header_1_0(fh, dict(descr="<f4", fortran_order=False, shape=stack))
                for radiograph in radiographs:
                    fh.write(np.ascontiguousarray(radiograph, "<f4").tobytes())

            write_atomic(out, write, args.force)
        seconds = time.perf_counter() - start
        if blank:
            warn(f"pose(s) {', '.join(map(str, blank[:10]))}{' ...' if len(blank) > 10 else ''} see nothing of the "
                 f"model (it lies outside their cone): check --isocentre (default the volume's centre) and the pose "
                 f"table")
        kind = "transmitted intensities" if args.intensity else "line integrals"
        how = f"ray traced, tolerance {tolerance:g}" if args.method == "raytrace" else "splatted"
        finish(outputs, [f"{len(cameras)} radiograph(s) of {H}x{W} ({kind}, {how}) of "
                         f"{kept_words(wv.kept, wv.n_voxels)} in {seconds:.2f} s, {seconds / len(cameras):.3f} s each, "
                         f"on {renderer.cc.info.name}: {out}"])
    return 0


def table_poses(geometry, table) -> list:
    """``poses(**geometry)`` of a pose table's rows; a pose it refuses is named by its number in ``table`` (the
    names in the message, ``dso=`` and the like, are the table's columns)."""
    from ..model.conebeam import poses

    try:
        return poses(**geometry)
    except InputError:
        for number, row in enumerate(geometry["rows"], 1):
            try:
                poses(**dict(geometry, rows=[row]))
            except InputError as refused:  # a row alone is its pose 1
                raise InputError(f"pose table {table}, pose {number}: {str(refused).removeprefix('pose 1: ')}") \
                    from None
        raise


@contextmanager
def pose_named(table, number, row):
    """A refusal of pose ``number`` (from 1) of pose table ``table`` (its view, or splatting it) named by them, its
    fixes in that pose's words: the dso, dsd or projection matrix of its ``row`` where the row gives them, which the
    command's --dso, --dsd and --pixel do not override."""
    try:
        yield
    except ClwaveError as exc:
        if "p00" in row:  # the header's columns are a matrix's or a pose's (matrix_columns)
            narrow, distance = "--size, or its row's matrix", "a matrix in its row whose source distance is"
        else:
            narrow = "--size, --pixel or " + ("the dsd in its row" if "dsd" in row else "--dsd")
            distance = "a dso in its row" if "dso" in row else "--dso"
        words = CommandWords(narrow, distance, "clwave drr --method raytrace")
        exc.cli, exc.worded = f"pose table {table}, pose {number}: {exc.cli_message(words)}", False
        raise


def log_window(window):
    """The window on ``-ln I`` (the line integrals, at least 0) of an ``--intensity`` picture's ``--window LO,HI`` of
    intensities (LO white, HI black); "auto" stays the percentiles (of ``-ln I``, so of ``I``)."""
    if window == "auto":
        return window
    lo, hi = window
    if not 0 < lo < hi:
        raise InputError(f"--window {lo:g},{hi:g}: an --intensity radiograph's window is two intensities 0 < LO < HI "
                         "(LO white, HI black), e.g. 0.01,1")
    return float(-np.log(hi)), float(-np.log(lo))


def add_parser(sub):
    from ..model.geometry import VIEWS

    # no --tf, --tf-window or --classify: a radiograph is line integrals of the scalar (or mu), never of colours
    p = add_command(sub, "drr", "digitally reconstructed radiographs: cone-beam X-rays of many poses", run,
                    "output .npy or .tif/.tiff (N, H, W) float32 stack, or .png for one pose", classify=False)
    p.add_argument("--method", choices=["splat", "raytrace"], default="splat",
                   help="splat (default): perspective wavelet splatting; raytrace: the ray tracer's X-ray mode, "
                        "within --tolerance of the exact line integrals (near or wide cones and Haar models, which "
                        "splatting refuses; on CPUs often as fast: docs/known-gaps.md §13)")
    p.add_argument("--tolerance", type=float, help="--method raytrace: absolute error per line integral "
                   "(default 1e-3)")
    p.add_argument("--view", choices=VIEWS, help="one pose from a RAS volume's side instead of --poses: anterior "
                   "(AP: the patient's left on the image's right), posterior, left, right, inferior, superior "
                   "(docs/coordinates.md §2)")
    p.add_argument("--poses", help="CSV pose table: a header line naming columns among azimuth, "
                   "elevation, roll, dso, dsd, offset_u, offset_v, isocentre_x/_y/_z (degrees, world units), or "
                   "p00..p23 (a 3x4 projection matrix), then one pose a line; # starts a comment line "
                   "(docs/coordinates.md §5)")
    g = p.add_argument_group("detector (defaults for every pose)")
    g.add_argument("--size", default="512", help="detector pixels N or HxW (default 512)")
    g.add_argument("--pixel", default="1.0", help="detector pixel spacing, or DV,DU (world units; default 1)")
    g.add_argument("--dso", type=float, default=1000.0, help="source-to-isocentre distance (default 1000)")
    g.add_argument("--dsd", type=float, default=1500.0, help="source-to-detector distance (default 1500)")
    g.add_argument("--offset", default="0,0", help="the detector's shift A,B along its columns (u) and up its "
                   "rows (v): its centre's position from the principal point, which lies at -A,-B from the centre "
                   "(TIGRE's offDetector; default 0,0)")
    g.add_argument("--isocentre", help="world X,Y,Z the principal ray passes, RAS+ millimetres for medical files "
                   "(DICOM's LPS, e.g. an RT Plan's IsocenterPosition: X and Y negated) (default: the volume's "
                   "centre, its world origin; a pose table's isocentre_x/_y/_z columns override it)")
    g.add_argument("--intensity", action="store_true", help="Beer-Lambert transmitted intensity exp(-line "
                   "integral) instead of the line integrals (a --hu-to-mu CT: mu per mm); a .png shows it as "
                   "radiographs are, -ln I windowed (bone bright; --window LO,HI in intensities, LO white)")
    g.add_argument("--signed", action="store_true", help="write the line integrals of a model below 0 on the whole "
                   "(not attenuation: refused without it, e.g. a CT in Hounsfield units read without --hu-to-mu)")
    add_device_options(g)
    p.set_defaults(words=CommandWords("--size, --pixel or --dsd", "--dso", "clwave drr --method raytrace"))
    return p
