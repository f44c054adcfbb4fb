"""``clwave info``: the OpenCL platforms and devices, and the one chosen; ``clwave info FILE``: what a ``.clw`` file's
header holds, or what a volume file's header declares, without reading a coefficient or a voxel."""

from __future__ import annotations

import json
import math

import numpy as np

from ..errors import InputError
from .options import error_words, file_size, kept_words
from .reading import READING, add_reading_options, flag, is_given, numbers, option, parse_spacing


def run(args):
    if args.file is not None:
        return describe(args)
    given = _reading(args)
    if given:
        raise InputError(f"{', '.join(given)} {'say' if len(given) > 1 else 'says'} how a FILE is read: give the FILE, "
                         f"or leave {'them' if len(given) > 1 else 'it'} out")
    from ..device.context import list_devices, requested_device, select_device
    from ..device.programs import selftest

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
        from ..device.context import ComputeContext
        seconds = selftest(ComputeContext.get(chosen.id))
        print(f"self-test kernel built in {seconds:.2f} s and ran correctly on {chosen.name}")
    return 0


def describe(args):
    """``clwave info FILE``: the header of a ``.clw`` (io/clw_info.py) or of a volume file (``loaders.describe``)."""
    if args.check or args.device is not None:
        raise InputError("--check and --device are about the OpenCL devices; leave them out with a FILE")
    if args.file.lower().endswith(".clw"):
        from ..io.clw_info import describe_clw

        given = _reading(args)
        if given:
            them = "them" if len(given) > 1 else "it"
            raise InputError(f"{', '.join(given)} {'say' if len(given) > 1 else 'says'} how a volume file is read; "
                             f"{args.file} is a .clw file, a model made already: leave {them} out")
        facts = describe_clw(args.file)
        lines = _clw_lines(facts)
    else:
        from ..io.loaders import describe as describe_volume

        shape = None if args.shape is None else numbers(args.shape, "--shape", (3, 4), int)
        facts = _as_read(args, describe_volume(args.file, series=args.series, level=args.level,
                                               frame=args.frame, shape=shape, dtype=args.dtype,
                                               byte_order=args.byte_order))
        lines = _volume_lines(facts)
    if args.json:
        print(json.dumps(facts, indent=2))
    else:
        print("\n".join(f"{name:<10} {text}" for name, text in lines))
    return 0


#: the keys ``clwave info --json`` adds to a volume file's facts (:data:`clwave.io.loaders.DESCRIBED`): its geometry as
#: the commands read it (:func:`_as_read`)
GEOMETRY = ("unit", "box", "spacing_option", "reading")


def _reading(args) -> list:
    """The reading options given (``--spacing 10,5,5``'s ``--spacing``)."""
    return [option(args, n) for n in _given(args)]


def _given(args) -> dict:
    """The reading options given, by name, as given (``--nan 0`` too: 0 == False)."""
    return {n: getattr(args, n) for n in READING if is_given(args, n)}


def _as_read(args, facts) -> dict:
    """A volume file's facts with what the reading options make of them: ``spacing`` the one the commands will use
    (``--spacing`` over the file's; ``spacing_in_file`` still the file's), ``unit`` the world unit (``--unit``, else the
    file's length unit, :func:`clwave.io.loaders.world_unit`), ``shape``, ``spacing`` and ``origin`` turned into RAS+
    by ``--orientation``, ``box`` the world size (x, y, z) where the shape and spacing are known, ``spacing_option``
    the ``--spacing`` text that gives that spacing (z first, along the axes as stored), and ``reading``: the options
    given, as given."""
    from ..io.loaders import check_orientation, world_unit
    from ..io.loaders.shared import stated_affine, to_canonical

    if args.spacing is not None:
        facts.update(spacing=[float(d) for d in parse_spacing(args.spacing)])
        if facts["origin"] is None:  # no file places it: load's origin
            facts.update(origin=[0.0] * 3, obliquity=0.0)
    known = facts["shape"] is not None and facts["spacing"] is not None
    option = None if facts["spacing"] is None else "--spacing " + _digits(facts["spacing"], ",")
    turn = check_orientation(facts["format"], args.orientation)
    if turn is not None and known:  # as load turns the volume, of a stand-in that holds no voxel
        shape = facts["shape"][:3]
        affine = stated_affine(turn, shape, facts["spacing"], facts["origin"] or [0.0] * 3)
        stand_in, spacing, origin, _ = to_canonical(np.broadcast_to(np.float32(0), shape), affine)
        facts.update(shape=list(stand_in.shape) + facts["shape"][3:], spacing=list(spacing), origin=list(origin))
    box = None if not known else [n * d for n, d in zip(facts["shape"][2::-1], facts["spacing"][::-1])]
    unit = args.unit or world_unit(args.file)
    return dict(facts, unit=unit, box=box, spacing_option=option, reading=_given(args))


def _clw_lines(f) -> list:
    z, y, x = f["shape"]
    extent = _extent(f["shape"], f["spacing"])
    unit = f" {f['unit']}" if f["unit"] else ""  # none recorded (a file of before session 19: unknown)
    lines = [("file", f"{f['file']}: {file_size(f['bytes'])}, a wavelet model (.clw)"),
             ("volume", f"{x} x {y} x {z} voxels (x, y, z), spacing {_digits(f['spacing'][::-1])}{unit} "
                        f"(x, y, z), {_placed(f['origin'], f['shape'], f['spacing'], extent)}"),
             ("model", f"{f['levels']} level{'s' * (f['levels'] != 1)}, {f['channels']} channel"
                       f"{'s' * (f['channels'] != 1)} in {len(f['groups'])} group{'s' * (len(f['groups']) != 1)}"
                       f"{', interpolating' if f['interpolate'] else ''}")]
    for gi, g in enumerate(f["groups"]):
        values = "float32 values" if g["quantisation"] is None else f"quantised, step {g['quantisation']:.3g}"
        which = f"channel{'s' * (len(g['channels']) != 1)} {', '.join(map(str, g['channels']))}"
        lines.append((f"group {gi}", f"{which}: {g['wavelet']} wavelet (order {g['order']}), keeps "
                                     f"{kept_words(g['kept'], x * y * z)}, {values}"))
    if f["focus"] is not None:
        lines.append(("focus", f"centre {_lengths(f['focus'][0], extent)}, sigma {f['focus'][1]:g}"))
    tf = f["transfer_function"]
    if tf is not None:
        window = tf.get("window")
        values = [row[0] for row in tf["points"]]
        window = (" .. ".join(f"{v:g}" for v in window) if isinstance(window, list) else window
                  or f"none (points are values, {min(values):g} .. {max(values):g})")
        when = "while rendering" if f["channels"] == 1 else "before the transform"
        lines.append(("transfer", f"{tf.get('name') or 'unnamed'}, window {window}, {len(tf['points'])} points "
                                  f"(classified {when}), opacities per {_opacity_unit(tf, f, unit)}"))
    if f["value_range"] is not None:
        lo, hi = f["value_range"]
        lines.append(("values", f"{lo:g} .. {hi:g}, the input's range (a transfer function classifies the field "
                                f"clamped to it)"))
    elif f["channels"] == 1:
        lines.append(("values", "the input's range not recorded (a file of before the nineteenth session: a transfer "
                                "function classifies the field unclamped)"))
    lines.append(("error", f"{error_words(f['model_error'])}: the whole file's model against its input (measured by "
                           f"clwave compress)" if f["model_error"] is not None else "the model's error against its "
                           "input not recorded (clwave compress records it where it reads the input whole, since the "
                           "twentieth session)"))
    if f["noise_sigma"] is not None:
        lines.append(("noise", _noise(f["noise_sigma"])))
    if f["subtracted"]:
        lines.append(("subtracted", f"{f['subtracted']:g} from the input's values (--subtract; transfer functions in "
                                    f"the input's units)"))
    if f["obliquity"]:
        lines.append(("oblique", _oblique(f["obliquity"])))
    if f["photo"]:
        lines.append(("photo", "a photo's colour and alpha, not classified: shaded ray tracing needs the original "
                               "volume compressed with --tf photo or another preset (docs/model.md §5)"))
    if f["provenance"]:  # absent before the twenty-third session, and for a model of no file (a phantom, an array)
        frame = f["provenance"]["frame"]
        lines.append(("from", f["provenance"]["file"] + ("" if frame is None else f", frame {frame} (--frame)")))
    if f["modality"]:  # a DICOM series', since the twenty-fourth session
        units = f["modality"]["units"]
        lines.append(("modality", f["modality"]["name"] + (f", values in {units}" if units else "")))
    return lines


def _noise(sigmas) -> str:
    """The input's noise level recorded in a .clw, in words (docs/model.md §2)."""
    if all(s is None for s in sigmas):
        return "none measured: the finest band of the input does not look like noise (a clean or sharp volume)"
    said = ", ".join("not noise-like" if s is None else f"sigma {s:.3g}" for s in sigmas)
    return (f"{said}{' per channel' if len(sigmas) > 1 else ''}, the input's, in its units, measured in the finest "
            f"band (--noise K keeps the details above K times their band's)")


def _opacity_unit(tf, f, unit) -> str:
    """The length a stored transfer function's opacities are per, in words (docs/model.md §5)."""
    if tf["opacity_unit"] is None:
        return f"voxel (the smallest spacing, {_lengths([min(f['spacing'])], _extent(f['shape'], f['spacing']))}{unit})"
    length = tf["opacity_unit"]
    return f"{length:g}{unit or (' world unit' if length == 1 else ' world units')}"


def _oblique(degrees) -> str:
    return (f"{degrees:.2f} degrees to its scanner's axes, kept on its own grid: world axes and cone-beam poses are "
            f"the volume's, not the scanner's (docs/coordinates.md §1)")


def _volume_lines(f) -> list:
    from ..io.loaders import RAS_FORMATS

    lines = [("file", f"{f['file']}: {file_size(f['bytes'])}, {f['format']}")]
    if f["series"]:  # a DICOM series: what a PACS viewer lists it by
        from ..io.loaders.dicom import series_name

        series, study, patient = f["series"], f["series"]["study"], f["series"]["patient"]
        name = series_name(series)
        units = f"values in {series['units']}" if series["units"] else ""
        said = [name, series["modality"], units, series["uid"] if series["uid"] not in name else ""]
        lines.append(("series", ", ".join(s for s in said if s)))
        said = [study["date"], study["description"] and f"'{study['description']}'",
                study["accession"] and f"accession {study['accession']}", study["id"] and f"ID {study['id']}"]
        if any(said):
            lines.append(("study", ", ".join(s for s in said if s)))
        if patient["name"] or patient["id"]:  # PHI: here, on the user's terminal, as DICOM viewers show it; never
            said = [patient["name"], patient["id"] and f"ID {patient['id']}"]  # in a file clwave writes
            lines.append(("patient", ", ".join(s for s in said if s)))
    if f["stored_shape"] is not None:  # read whole: weighed as the file stores it, its axes in the file's order
        resampled = "" if not f["resampled"] else ", its sheared grid resampled onto a straight one wider by its " \
            "shifts" if f["nifti"] else ", resampled onto an even, straight stack (a gantry tilt, uneven slices)"
        stored = f" (stored as {f['stored_dtype']})" if f["stored_dtype"] else ""
        read = ", a time series" if f["time"] else f"{stored}{resampled}"
        lines.append(("stored", f"{' x '.join(map(str, f['stored_shape']))} values of {f['dtype']}, in the file's "
                                f"order of axes{read}"))
    if f["shape"] is not None and not f["refused"]:  # a time series: one volume's, where --frame picks it
        z, y, x = f["shape"][:3]
        lines.append(("volume", f"{x} x {y} x {z} voxels (x, y, z), {f['channels']} channel"
                                f"{'s' * (f['channels'] != 1)} of {f['dtype']}"))
    unit = f" {f['unit']}" if f["unit"] else ""
    if f["spacing"] is not None:
        extent = _extent(f["shape"] or f["stored_shape"], f["spacing"])
        # the --spacing that gives it, to copy (z first); before --orientation turns the axes
        given = "spacing" in f["reading"]
        stated = "orientation" in f["reading"]
        turned = f", before --orientation {f['reading']['orientation']} turns it" if stated else ""
        missing = "" if given or f["spacing_in_file"] else ": none in the file, give yours"
        place = f"{_digits(f['spacing'][::-1])}{unit} (x, y, z; {f['spacing_option']}{' given' * given}" \
                f"{turned}{missing}), {_placed(f['origin'], f['shape'], f['spacing'], extent)}"
        lines.append(("spacing", place + (" (RAS+)" if f["format"] in RAS_FORMATS or stated else "")))
    elif not f["time"]:
        lines.append(("spacing", "found with the voxels when the file is read (1 where it gives none): "
                                 "--spacing DZ,DY,DX sets it"))
    if f["box"] is not None:
        words = unit or (" in --spacing's unit" if "spacing" in f["reading"] else
                         " world units (no length unit in the file)")
        lines.append(("box", f"{_digits(f['box'])} (x, y, z){words}"))
    values = {n: v for n, v in f["reading"].items() if n in ("subtract", "hu_to_mu", "nan")}
    if values:
        lines.append(("values", f"{', '.join(flag(n) + ('' if v is True else f' {v:g}') for n, v in values.items())}"
                                f": applied as the values are read (not read here)"))
    if "labels" in f["reading"]:
        lines.append(("labels", "a label map (--labels): a wavelet above Haar is warned of (docs/model.md §5)"
                      if f["reading"]["labels"] else "no label map (--no-labels), whatever its values look like"))
    if f["time"]:
        t = f["time"]
        step = "" if t["step"] is None else f", {t['step']:g} {t['unit'] or '(no unit)'} apart"
        points = "time points" if t["along"] == "time" else f"planes along {t['along']}"
        last = t["points"] - 1
        picked = f"--frame {t['frame']} read" if t["frame"] is not None else \
            f"--frame K picks one, 0 .. {last} (or -{last + 1} .. -1 from the end); without it compress, render, " \
            "progressive, drr and view refuse the file"
        lines.append(("time", f"{t['points']} {points}{step}: {picked}"))
    if f["rescale"]:
        (slope, intercept), more = f["rescale"][0], len(f["rescale"]) - 1
        lines.append(("rescale", f"slope {slope:g}, intercept {intercept:g}"
                                 f"{f' ({more + 1} different pairs across its slices)' if more else ''}"))
    if f["padding"] is not None:
        lines.append(("padding", "none" if not f["padding"] else
                      f"stored {' .. '.join(map(str, dict.fromkeys(f['padding'])))} (outside the patient): set to "
                      f"the series' least other value when read"))
    if f["obliquity"]:
        lines.append(("oblique", _oblique(f["obliquity"])))
    return lines + _nifti_lines(f["nifti"]) + _fits_lines(f["fits"], f["shape"], f["spacing"]) + _segy_lines(f["segy"])


def _nifti_lines(n) -> list:
    """A NIfTI header's orientation, shear, scaling and intent (``loaders.nifti.header_facts``)."""
    if n is None:
        return []
    codes = f"sform_code {n['sform_code']}, qform_code {n['qform_code']}"
    if n["affine_from"] == "none":
        where = f"none in the file ({codes}): nibabel's fallback, {n['orientation']}, assumed"
    else:
        differ = f"; the {'q' if n['affine_from'] == 'sform' else 's'}form differs" if n["forms_differ"] else ""
        where = f"stored {n['orientation']}, from the {n['affine_from']} (nibabel's choice; {codes}){differ}"
    lines = [("orient", where)]
    if n["sheared"]:
        lines.append(("sheared", f"{n['sheared']:.2f} degrees (its axes not at right angles, as an uncorrected gantry "
                                 f"tilt's): resampled onto a straight grid when read, linearly"))
    if "scl_slope" in n:
        lines.append(("scaled", f"scl_slope {n['scl_slope']:g}, scl_inter {n['scl_inter']:g} (applied as read)"))
    if n["intent"] == "label":
        lines.append(("intent", "labels (NIFTI_INTENT_LABEL): compress with --wavelet haar (docs/model.md §5)"))
    return lines


def _fits_lines(c, shape, spacing) -> list:
    """A FITS cube's HDU, values and axes (``loaders.fits.header_facts``), and the ``--spacing`` that makes its
    spectral axis (x) as deep as its sky (``shape`` and ``spacing``, dz the celestial pixels' aspect) is wide (yt's
    ``spectral_factor="auto"``)."""
    if c is None:
        return []
    scaling = ", ".join(f"{k} {v:g}" for k, v in c["scaling"].items())
    axes = []
    for n, a in enumerate(c["axes"], 1):
        step = "" if a["step"] is None else f", {a['step']:g}{' ' + a['unit'] if a['unit'] else ''} a pixel"
        becomes = f"-> {a['axis']}{' reversed' * bool(a['flipped'])}" if a["axis"] is not None else \
            "one plane (--frame)" if a["length"] > 1 else "dropped"
        axes.append(f"{n} {a['type'] or '(no CTYPE)'} ({a['length']}{step}) {becomes}")
    name = f" ({c['name']})" if c["name"] else ""
    scaled = f" ({scaling}, applied as read)" if scaling else ""
    unit = c["unit"] or "no unit (no BUNIT)"
    dz, dy = spacing[:2]
    deep = _digits((dz, dy, max(shape[0] * dz, shape[1] * dy) / shape[2]), ",")
    return [("cube", f"HDU {c['hdu']}{name}, values in {unit}{scaled}; NaN (and BLANK) are no data: --nan VALUE gives "
                     "them a value"),
            ("axes", "; ".join(axes) + "; in pixels, north up and east left seen from +x (docs/coordinates.md §1); "
                     f"--spacing {deep} makes the spectral axis as deep as the sky is wide")]


def _segy_lines(s) -> list:
    """A SEG-Y survey's lines, samples and coordinates (``loaders.segy.header_facts``)."""
    if s is None:
        return []
    lines = [f"{first}..{last} (step {step})" for first, last, step in (s["inlines"], s["crosslines"])]
    bins = f"from its {s['coordinates']} coordinates (scalar {s['scalar']})" if s["coordinates"] else \
        "taken as 1: no CDP or source coordinates in its trace headers"
    mirrored = ", along -y: inlines, crosslines and up are left-handed on the map" if s["mirrored"] else ""
    return [("survey", f"inlines {lines[0]} along x, crosslines {lines[1]} along y{mirrored}, {s['samples']} samples "
                       f"a trace, down along -z; format {s['format']} ({s['format_name']}), {s['sorting']}-sorted"),
            ("bins", f"{_digits(s['spacing'][:0:-1])} (inline, crossline) {bins}"),
            ("z", s["z"])]


def _extent(shape, spacing) -> float:
    """The volume's largest length in world units: what :func:`_lengths` rounds to."""
    return max(n * abs(d) for n, d in zip(shape[:3], spacing))


def _placed(origin, shape, spacing, extent) -> str:
    """Where a volume of ``shape`` (z, y, x, ...; None: unknown) and ``spacing`` lies, in words a user of any format
    reads right: clwave's ``origin`` (x, y, z) is its centre (docs/coordinates.md §1; "origin" in a file is often its
    first voxel), and the voxel of least x, y, z (an MRC map's first voxel, at its header's origin as ChimeraX reads
    it) is half the box less a voxel from it (until trial29 the centre alone, printed as "origin")."""
    if shape is None:  # not known before the voxels are read: no corner
        return f"centre {_lengths(origin, extent)}"
    corner = np.asarray(origin, float) - np.abs(spacing[::-1]) * (np.array(shape[2::-1]) - 1) / 2
    return f"centre {_lengths(origin, extent)}, corner voxel (least x, y, z) {_lengths(corner, extent)}"


def _lengths(values, extent, sep=", ") -> str:
    """World lengths rounded to a millionth of the volume's ``extent`` (a float32 affine's noise, -9.5e-07 for 0,
    is below it), so that no sign of nothing is printed; the JSON keeps the numbers as they are."""
    decimals = -math.floor(math.log10(extent * 1e-6)) if extent > 0 else 6
    return sep.join(f"{round(v, decimals) + 0.0:g}" for v in values)


def _digits(values, sep=", ") -> str:
    """Lengths each with the fewest significant digits that give its float32 (what the renderers compute in) back
    (NumPy's shortest repr): a spacing or box of very different magnitudes (5000 : 0.0014) printed whole, and an
    echoed ``--spacing`` that, pasted back, gives the same geometry."""
    return sep.join(text[:-2] if (text := str(np.float32(v))).endswith(".0") else text for v in values)


def add_parser(sub):
    p = sub.add_parser("info", help="list OpenCL platforms and devices, and the one chosen; with FILE, what a .clw "
                                    "file or a volume file's header holds")
    p.add_argument("file", nargs="?", help="a .clw file, or a volume file or folder: its header, read without its "
                                           "coefficients or voxels")
    p.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    p.add_argument("--check", action="store_true", help="also build and run a self-test kernel")
    p.add_argument("--json", action="store_true", help="print JSON (with FILE: the same keys for every volume "
                                                       "format, null where a format does not give the fact; "
                                                       "docs/coordinates.md §4)")
    add_reading_options(p)  # a volume FILE's geometry as the commands read it
    p.set_defaults(run=run)
