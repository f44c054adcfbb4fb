"""The input of the commands and how it is read: the reading options (``--spacing``, ``--series``, ``--chunks``...),
their texts parsed and checked, the names ``args`` gives them, and the volume they read (:func:`read_volume`)."""

from __future__ import annotations

import argparse
from functools import partial

from ..device.memory import check_fits
from ..errors import InputError, finite_number
from ..io.images import UNIT_METRES

#: host bytes per float32 value of the volume below which decomposing and thresholding it cannot run: the
#: in-memory model peaks at 3 (RGBA) to 9 (scalar) times the volume; work beyond 4 times what is available
#: is refused before it starts
MODEL_BYTES_PER_VALUE = 16


def numbers(text, name, counts, kind=float, sep=",") -> tuple:
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


def parse_spacing(text) -> tuple:
    """``--spacing DZ,DY,DX`` (or one number for all three) as three positive voxel sizes, or the one line that
    refuses it: the one check of every command's ``--spacing``, ``clwave info FILE``'s too."""
    from ..model.geometry import WORLD_RANGE

    spacing, (low, high) = numbers(text, "--spacing", (1, 3)), WORLD_RANGE
    # within the world lengths clwave renders (a voxel of 1e308 or 1e-320 was info's internal error)
    if not all(low <= d <= high for d in spacing):
        raise InputError(f"--spacing {text} must be positive voxel sizes DZ,DY,DX (or one) from {low:g} to {high:g}, "
                         f"e.g. 1,0.5,0.5")
    return spacing * 3 if len(spacing) == 1 else spacing


def add_input_options(p):
    p.add_argument("input", help="volume file, DICOM folder, .clw file, or phantom:NAME[:N]")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction,
                   help="show the progress of long steps on stderr, a log's too (default: on a terminal only); "
                        "--no-progress: never")
    add_reading_options(p)
    c = p.add_argument_group("chunked work (a chunked input; docs/chunked.md)")
    w = c.add_mutually_exclusive_group()
    w.add_argument("--workers", type=int, help="a local Dask cluster of N worker processes (default: threads)")
    w.add_argument("--scheduler", help="address tcp://HOST:PORT of a running Dask scheduler")


#: the options of :func:`add_reading_options`, as ``args`` names them
READING = ("shape", "dtype", "byte_order", "spacing", "series", "subtract", "hu_to_mu", "nan", "level", "frame",
           "chunks", "orientation", "unit", "labels")


def add_reading_options(p):
    """How a volume file is read (:func:`read_volume`): the input commands' and ``clwave info FILE``'s."""
    g = p.add_argument_group("reading the input")
    g.add_argument("--shape", help=".raw only: Z,Y,X or Z,Y,X,C")
    g.add_argument("--dtype", help=".raw: numpy dtype, e.g. uint16; an MRC map of bytes (mode 0): uint8 or int8, "
                                   "read unsigned or signed (default signed, as MRC2014 says, unless IMOD's stamp)")
    g.add_argument("--byte-order", choices=["<", ">"], help=".raw only: little (<) or big (>) endian")
    g.add_argument("--spacing", help="voxel spacing DZ,DY,DX, z first (or one number), in the file's unit (or "
                                     "--unit's); overrides the file's; 'clwave info FILE' prints it as --spacing")
    g.add_argument("--unit", choices=tuple(UNIT_METRES), help="the world unit, the spacing's (default the file's)")
    g.add_argument("--orientation", metavar="CODES", help="an input with no orientation (npy, raw, TIFF, a folder of "
                   "slices, Zarr, HDF5, MRC): where its x, y, z axes point, e.g. LPS (x left, y posterior, z superior; "
                   "nibabel's codes), turned into RAS+ as DICOM is")
    g.add_argument("--series", metavar="NUMBER", help="DICOM folder, tree or DICOMDIR with several series: the "
                   "SeriesNumber its listing shows, or the description or SeriesInstanceUID; of several studies "
                   "STUDY/NUMBER, the study as the listing heads it (1/2), or by its date, accession or ID")
    labels = g.add_mutually_exclusive_group()
    labels.add_argument("--labels", action="store_const", const=True, help="the input is a label map (a "
                        "segmentation), whatever its values look like (default: a NIfTI's intent, else a guess from "
                        "the values; docs/model.md §5)")
    labels.add_argument("--no-labels", dest="labels", action="store_const", const=False,
                        help="the input is no label map, whatever its values look like")
    g.add_argument("--subtract", type=float, help="value subtracted so outside is ~0 (air, water; CT in HU: -1000); "
                   "recorded, so --tf and --tf-window stay in the input's units")
    g.add_argument("--hu-to-mu", action="store_true", help="CT: Hounsfield units to attenuation per mm")
    g.add_argument("--nan", type=float, metavar="VALUE", help="the value of NaN voxels (no data: FSL and SPM write "
                   "NaN outside their masks), in the input's units, e.g. 0; without it NaN is refused")
    g.add_argument("--level", type=int, help="OME-Zarr: the multiscale level to read (default 0, the finest)")
    g.add_argument("--frame", type=int, metavar="K", help="a time series (a 4-D NIfTI, MGH frames, a TIFF's axis T, "
                   "an OME-Zarr's axis t, a FITS cube's planes, Stokes I/Q/U/V): the 0-based time point to read, "
                   "negative from the end (-1: the last); 'clwave info FILE' lists them")
    g.add_argument("--chunks", help="read chunk by chunk, never whole (docs/chunked.md): auto, off, or a chunk "
                                    "edge N (default: Zarr and HDF5 always, .npy/.raw/.nii/TIFF from 1 GiB)")


def read_volume(args):
    """The Volume named by ``args.input`` (a file, a folder or ``phantom:NAME[:N]``)."""
    from ..io.loaders import load
    from ..io.phantoms import phantom
    from ..model.volume import Volume

    spec = args.input
    spacing = None if args.spacing is None else parse_spacing(args.spacing)
    if spec.startswith("phantom:"):
        given = [option(args, n) for n in READING if n not in ("spacing", "subtract") and is_given(args, n)]
        if given:
            raise InputError(f"{', '.join(given)} cannot apply to {spec}: a phantom is not read from a file")
        parts = spec.split(":")
        if len(parts) > 3 or (len(parts) == 3 and not parts[2].isdigit()):
            raise InputError(f"{spec!r}: write phantom:NAME or phantom:NAME:N (N voxels per axis)")
        n = int(parts[2]) if len(parts) == 3 else 128
        check_model_fits(args, n ** 3, 1, f"decomposing a {n}^3 phantom", "choose a smaller N")
        vol = phantom(parts[1], n=n)
        if spacing is None and not args.subtract:
            return vol
        subtract = finite_number(args.subtract or 0.0, "--subtract")  # as load(subtract=) subtracts it
        data = vol.data - vol.data.dtype.type(subtract)
        return Volume(data, spacing=vol.spacing if spacing is None else spacing, subtracted=subtract)
    shape = None if args.shape is None else numbers(args.shape, "--shape", (3, 4), int)
    # weighed by the size the file declares, before its voxels are read
    fits = partial(check_model_fits, args, what="decomposing this volume",
                   hint="read it chunk by chunk (--chunks auto: Zarr, HDF5, .npy, .raw, .nii, .mgh, MRC, FITS, TIFF; "
                        "gunzip a .nii.gz first, a .mgz into a .mgh), or crop or subsample it")
    return load(spec, shape=shape, dtype=args.dtype, spacing=spacing, byte_order=args.byte_order,
                series=args.series, level=args.level, frame=args.frame,
                chunks=parse_chunks(args.chunks),
                nan=args.nan, subtract=args.subtract or 0.0, hu_to_mu=args.hu_to_mu, fits=fits,
                orientation=args.orientation, unit=args.unit, labels=args.labels)


def check_model_fits(args, voxels, channels, what, hint):
    """Refuse (a ``HostMemoryError``) a volume of ``voxels`` and ``channels`` whose model would not fit in the host's
    memory (``MODEL_BYTES_PER_VALUE`` a value; ``--tf`` classifies a scalar into four channels first)."""
    classified = getattr(args, "tf", None) and getattr(args, "classify", "pre") == "pre"
    check_fits(MODEL_BYTES_PER_VALUE * voxels * (4 if classified else channels), what, hint)


def parse_chunks(text):
    """``load``'s ``chunks=`` from ``--chunks auto|off|N``."""
    if text is None or text == "auto":
        return text
    if text == "off":
        return False
    if not text.isdigit() or int(text) < 2:
        raise InputError(f"--chunks {text} must be auto, off or a chunk edge N >= 2 (voxels)")
    return int(text)


def flag(name: str) -> str:
    """The command line's option of an ``args`` attribute: ``hu_to_mu`` -> ``--hu-to-mu``."""
    return "--" + name.replace("_", "-")


def is_given(args, name) -> bool:
    """Whether the option of ``args.name`` was given: a value (``--nan 0`` too: 0 == False) but no switch's off
    (``--hu-to-mu``'s False), or ``--no-labels`` (False; None where neither it nor ``--labels`` is given)."""
    value = getattr(args, name, None)
    return value is not None and (value is not False or name == "labels")


def option(args, name) -> str:
    """The option that gave ``args.name`` (:func:`flag`; ``--no-labels`` for ``labels`` False)."""
    return "--no-labels" if name == "labels" and getattr(args, name) is False else flag(name)
