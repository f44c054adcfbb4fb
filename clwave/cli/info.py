"""``clwave info``: the OpenCL platforms and devices, and the one chosen; ``clwave info FILE``: what a ``.clw`` file's
header holds, or what a volume file's header declares, without reading a coefficient or a voxel."""

from __future__ import annotations

import json
import math

from ..errors import InputError
from .options import file_size, kept_words, parse_series


def run(args):
    if args.file is not None:
        return describe(args)
    if (args.series, args.level) != (None, None):
        raise InputError("--series and --level choose what a FILE's header describes: give the FILE, or leave them "
                         "out")
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

        if (args.series, args.level) != (None, None):
            raise InputError(f"--series and --level choose within a DICOM folder or an OME-Zarr image; {args.file} "
                             f"is a .clw file: leave them out")
        facts = describe_clw(args.file)
        lines = _clw_lines(facts)
    else:
        from ..io.loaders import describe as describe_volume

        facts = describe_volume(args.file, series=parse_series(args.series), level=args.level)
        lines = _volume_lines(facts)
    if args.json:
        print(json.dumps(facts, indent=2))
    else:
        print("\n".join(f"{name:<10} {text}" for name, text in lines))
    return 0


def _clw_lines(f) -> list:
    z, y, x = f["shape"]
    extent = _extent(f["shape"], f["spacing"])
    lines = [("file", f"{f['file']}: {file_size(f['bytes'])}, a wavelet model (.clw)"),
             ("volume", f"{x} x {y} x {z} voxels (x, y, z), spacing {_lengths(f['spacing'][::-1], extent)} (x, y, z), "
                        f"origin {_lengths(f['origin'], extent)}"),
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
                                  f"(classified {when})"))
    if f["subtracted"]:
        lines.append(("subtracted", f"{f['subtracted']:g} from the input's values (--subtract; transfer functions in "
                                    f"the input's units)"))
    if f["obliquity"]:
        lines.append(("oblique", _oblique(f["obliquity"])))
    return lines


def _oblique(degrees) -> str:
    return (f"{degrees:.2f} degrees to its scanner's axes, kept on its own grid: world axes and cone-beam poses are "
            f"the volume's, not the scanner's (docs/coordinates.md §1)")


def _volume_lines(f) -> list:
    lines = [("file", f"{f['file']}: {file_size(f['bytes'])}, {f['format']}")]
    if f["stored_shape"] is not None:  # read whole: weighed as read, before the loader orders the axes
        resampled = "" if not f["resampled"] else ", its sheared grid resampled onto a straight one wider by its " \
            "shifts" if f["nifti"] else ", a gantry tilt resampled onto a straight stack wider by its shifts"
        stored = f" (stored as {f['stored_dtype']})" if f["stored_dtype"] else ""
        read = ", a time series, as stored" if f["time"] else f" as read{stored}{resampled}, before the loader " \
            f"orders them{'' if f['spacing'] else ' (its axes and spacing come with the voxels)'}"
        lines.append(("volume", f"{' x '.join(map(str, f['stored_shape']))} samples of {f['dtype']}{read}"))
    else:
        z, y, x = f["shape"][:3]
        lines.append(("volume", f"{x} x {y} x {z} voxels (x, y, z), {f['channels']} channel"
                                f"{'s' * (f['channels'] != 1)} of {f['dtype']}"))
    if f["spacing"] is not None:
        extent = _extent(f["shape"], f["spacing"])
        unset = "" if f["spacing_in_file"] else " (none in the file)"
        place = f"{_lengths(f['spacing'][::-1], extent)} (x, y, z){unset}, origin {_lengths(f['origin'], extent)}"
        if f["stored_shape"] is not None:
            place += " (µm for an OME-TIFF, an ImageJ stack's unit; as loaded)" if f["format"] == "tiff" else \
                " (RAS+ mm, as loaded)"
        lines.append(("spacing", place))
    if f["time"]:
        t = f["time"]
        step = "" if t["step"] is None else f", {t['step']:g} {t['unit'] or '(no unit)'} apart"
        lines += [("time", f"{t['points']} time points{step}"),
                  ("refused", f"when read (compress, render, drr, view): {f['refused']}")]
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
    return lines + _nifti_lines(f["nifti"])


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


def _extent(shape, spacing) -> float:
    """The volume's largest length in world units: what :func:`_lengths` rounds to."""
    return max(n * abs(d) for n, d in zip(shape[:3], spacing))


def _lengths(values, extent) -> str:
    """World lengths rounded to a millionth of the volume's ``extent`` (a float32 affine's noise, -9.5e-07 for 0,
    is below it), so that no sign of nothing is printed; the JSON keeps the numbers as they are."""
    decimals = -math.floor(math.log10(extent * 1e-6)) if extent > 0 else 6
    return ", ".join(f"{round(v, decimals) + 0.0:g}" for v in values)


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
    p.add_argument("--series", help="FILE a DICOM folder with several series: UID or 0-based index")
    p.add_argument("--level", type=int, help="FILE an OME-Zarr image: the multiscale level (default 0)")
    p.set_defaults(run=run)
