"""MRC and CCP4 maps (``.mrc``, ``.map``, ``.ccp4``, ``.rec``, ``.st``: cryo-EM maps, tomograms, tilt series), their
header read by mrcfile, their samples memory-mapped, whole or chunk by chunk."""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from ...errors import ClwaveWarning, FileFormatError, InputError, warn_outside
from .raw import read_memmap
from .shared import UNEVEN, OnDemand, as_array, check_declared_size, no_spacing, note

MRC_SUFFIXES = (".mrc", ".map", ".ccp4", ".rec", ".st")
_HEADER = 1024  # bytes before the extended header (nsymbt bytes), then the samples
_COMPLEX = {3: "complex int16", 4: "complex float32"}
_IMOD_STAMP = 1146047817  # "IMOD" (little-endian bytes)
#: Signed bytes (mode 0, MRC2014) whose steps of more than 128 between neighbours would be under WRAPPED as many read
#: unsigned: an unsigned 8-bit map, its values above 127 wrapped (sections evenly spaced, at most WRAP_SAMPLE bytes)
WRAPPED, WRAP_SAMPLE = 0.5, 1 << 22


def read_mrc(path, chunks, fits=None, warn_spacing=True, dtype=None):
    """``(data, spacing, origin)`` of an MRC2014 or CCP4 map as ``(z, y, x)``: the header read and checked by mrcfile
    (``permissive=False``: its map ID and machine stamp), then here before any sample is read (its mode, its
    dimensions, its axis order ``mapc``/``mapr``/``maps``, and the samples it declares against the file's size);
    the samples transposed from the file's (section, row, column) order to (z, y, x).  Spacing (Å) is the cell
    over its sampling along each axis, None where the header gives none (a warning unless ``warn_spacing`` is
    false); the first voxel is at the header's ``origin`` where it is finite, not 0 (at minus it in a file of IMOD's
    stamp, as IMOD defines it: :func:`_imod`), else at its start indices times the spacing (as ChimeraX places a
    map); ``origin`` is the volume's centre.  A volume stack is refused; an image stack
    (space group 0: a tilt series, a stack of particles) is read as a volume, with a warning.  Mode 0's bytes are
    signed (MRC2014) unless IMOD's stamp says they are not, or ``dtype`` (uint8 or int8) says how to read them; read
    signed, they are warned of where they look wrapped (:data:`WRAPPED`)."""
    header, offset = _header(path)
    import mrcfile.utils

    mode = int(header.mode)
    if mode in _COMPLEX:
        raise FileFormatError(f"{path} holds {_COMPLEX[mode]} samples (mode {mode}: a Fourier transform); clwave reads "
                              "real maps: transform it back to real space first")
    try:
        samples = mrcfile.utils.data_dtype_from_header(header)
    except ValueError:
        raise FileFormatError(f"{path}: its MRC header names mode {mode}, none clwave reads (0 int8, 1 int16, "
                              "2 float32, 6 uint16, 12 float16); the file is corrupt or packed (mode 101)") from None
    given = dtype is not None
    if given:
        samples = _bytes_as(path, mode, dtype)
    elif mode == 0 and _imod_unsigned(header):
        samples = np.dtype(np.uint8)
    stored = tuple(int(n) for n in (header.nz, header.ny, header.nx))  # sections, rows, columns
    if min(stored) < 1:
        raise FileFormatError(f"{path}: its MRC header declares {' x '.join(map(str, stored[::-1]))} columns, rows "
                              "and sections; each needs at least one")
    ispg = int(header.ispg)
    if mrcfile.utils.spacegroup_is_volume_stack(ispg) and stored[0] != int(header.mz):
        raise FileFormatError(f"{path} is a stack of volumes (space group {ispg}, {stored[0]} sections of "
                              f"{int(header.mz)}); clwave reads one volume: write one to a file of its own")
    axes = tuple(int(a) for a in (header.maps, header.mapr, header.mapc))  # of sections, rows, columns: 1 x .. 3 z
    if sorted(axes) != [1, 2, 3]:
        raise FileFormatError(f"{path}: its MRC header orders the axes mapc, mapr, maps = {axes[::-1]}, not an order "
                              "of x, y, z (1, 2, 3); the header is corrupt")
    check_declared_size(path, offset, math.prod(stored) * samples.itemsize, stored[::-1], gzip=False)
    if not given and samples == np.int8 and _wrapped(path, stored, offset):
        words = (f"{path}: its bytes (mode 0) are read signed, as MRC2014 says, but look wrapped (jumps of more than "
                 "128 between neighbours, as 127 next to -128, more than twice as many as read unsigned: an unsigned "
                 "8-bit map without IMOD's stamp): give ")
        warn_outside(ClwaveWarning(words + "dtype='uint8' to read them unsigned, dtype='int8' to keep them signed",
                                   cli=words + "--dtype uint8 to read them unsigned, --dtype int8 to keep them signed"))
    if ispg == 0 and stored[0] > 1:
        note(f"{path} is a stack of {stored[0]} 2-D images (space group 0: a tilt series or a stack of particles): "
             "read as the slices of a volume")
    spacing = _spacing(header)
    if spacing is not None and max(spacing) > UNEVEN * min(spacing):
        cell, sampling = header.cella.tolist(), (int(header.mx), int(header.my), int(header.mz))
        raise FileFormatError(f"{path}: its cell ({', '.join(f'{c:g}' for c in cell)} Å) over its sampling (mx, my, "
                              f"mz = {', '.join(map(str, sampling))}) gives voxels of "
                              f"{' x '.join(f'{d:.3g}' for d in spacing[::-1])} Å (x, y, z), more than {UNEVEN:g} "
                              f"times longer along one axis than another; the header is wrong: correct its cell or "
                              f"its mx, my, mz")
    source = OnDemand(partial(read_memmap, str(path), samples, stored, offset, "C"), stored, samples)
    data = as_array(source, chunks, fits=fits, path=path)
    data = data.transpose([axes.index(a) for a in (3, 2, 1)])  # (z, y, x)
    if spacing is None:
        if warn_spacing:
            no_spacing(path)
        return data, None, None
    start = np.zeros(3)  # x, y, z: the first voxel's index in the map's grid (nxstart: columns', ...)
    start[[a - 1 for a in axes[::-1]]] = [float(header.nxstart), float(header.nystart), float(header.nzstart)]
    given = np.array([float(header.origin.x), float(header.origin.y), float(header.origin.z)])
    given = -given if _imod(header)[0] else given
    step = np.array(spacing[::-1])
    first = given if np.any(given) and np.all(np.isfinite(given)) else start * step
    centre = first + step * (np.array(data.shape[:3][::-1]) - 1) / 2
    return data, spacing, tuple(float(c) for c in centre)


def world_unit(path) -> str | None:
    """"A" (ångström) where the header gives a voxel size, else None."""
    return "A" if _spacing(_header(path)[0]) is not None else None


def _header(path):
    """``(header, offset of the samples)``: mrcfile's header, checked as ``permissive=False`` checks it, its extended
    header's length (``nsymbt``) first, not negative and against the file's: mrcfile reads (allocates) all it
    declares."""
    import mrcfile
    from mrcfile.dtypes import HEADER_DTYPE
    from mrcfile.utils import byte_order_from_machine_stamp

    with open(path, "rb") as fh:
        raw = fh.read(_HEADER)
    try:
        order = byte_order_from_machine_stamp(raw[212:216]) if len(raw) == _HEADER else None
    except ValueError:
        order = None  # mrcfile names the problem
    if order is not None:
        extended, holds = int(np.frombuffer(raw, HEADER_DTYPE.newbyteorder(order))[0]["nsymbt"]), \
            path.stat().st_size - _HEADER
        if extended < 0:
            raise FileFormatError(f"{path}: its MRC header declares an extended header of {extended:,} bytes (nsymbt); "
                                  "the header is corrupt")
        if extended > holds:
            raise FileFormatError(f"{path}: its MRC header declares an extended header of {extended:,} bytes but the "
                                  f"file holds {holds:,} bytes after its 1,024-byte header; it is truncated or its "
                                  "header is wrong")
    try:
        with mrcfile.open(path, header_only=True, permissive=False) as mrc:
            return mrc.header.copy(), _HEADER + int(mrc.header.nsymbt)
    except ValueError as exc:
        raise FileFormatError(f"{path} is not an MRC/CCP4 map clwave reads: {exc} (mrcfile)") from None


def _imod(header) -> tuple:
    """``(stamped, flags)``: whether IMOD wrote the file (its stamp, "IMOD" at byte 152), and its imodFlags (at 156).
    IMOD's origin is "the origin of the coordinate system relative to the first pixel" (its mrc_format.txt; "defined
    in the opposite way in UCSF Chimera", its alterheader's manual): the first voxel at minus it, where ChimeraX,
    which ignores the stamp there, and mrcfile read the origin as the first voxel's place."""
    stamp, flags = np.frombuffer(header.tobytes(), header.nx.dtype, 2, 152)
    return int(stamp) == _IMOD_STAMP, int(flags)


def _imod_unsigned(header) -> bool:
    """Whether mode 0's bytes are unsigned: IMOD's stamp without its signed-bytes flag (bit 0 of imodFlags), as IMOD
    wrote every byte file before 4.2.23; MRC2014's mode 0 is signed."""
    stamped, flags = _imod(header)
    return stamped and not flags & 1


def _bytes_as(path, mode, given):
    """``dtype=`` of a map: uint8 or int8, how mode 0's bytes are read; refused for another mode or type."""
    if mode != 0:
        words = f"says how an MRC map's bytes (mode 0) are read; {path} holds mode {mode}: leave it out"
        raise InputError(f"dtype= {words}", cli=f"--dtype {words}")
    try:
        dtype = np.dtype(given)
    except TypeError:
        dtype = None
    if dtype not in (np.uint8, np.int8):
        raise InputError(f"dtype={given!r} of an MRC map of bytes must be 'uint8' (unsigned) or 'int8' (signed)",
                         cli=f"--dtype {given} of an MRC map of bytes must be uint8 (unsigned) or int8 (signed)")
    return dtype


def _wrapped(path, stored, offset) -> bool:
    """Whether a mode-0 map's bytes read signed look wrapped: steps of more than 128 between neighbours along its rows
    (127 next to -128 where unsigned it is 127 next to 128) more than 1 / :data:`WRAPPED` times as many as read
    unsigned (where a signed map's -1 next to 0 is 255 next to 0), on evenly spaced sections of at most
    :data:`WRAP_SAMPLE` bytes."""
    rows = np.memmap(path, np.int8, "r", offset, stored)[::max(1, math.prod(stored) // WRAP_SAMPLE)].astype(np.int16)
    signed = np.count_nonzero(np.abs(np.diff(rows)) > 128)
    return np.count_nonzero(np.abs(np.diff(rows & 0xFF)) > 128) < WRAPPED * signed


def _spacing(header):
    """``(dz, dy, dx)`` in Å: the cell's lengths over its sampling (mx, my, mz) along x, y, z; None where any is not
    a positive finite number (a cell of 0: no voxel size).  A length is its float32's shortest decimal (6254.72, not
    6254.7202): 13.48 Å over 464 voxels, not float32's noise over them, 13.4800005."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        size = [float(str(np.float32(length))) / float(n)
                for length, n in zip(header.cella.tolist(), (header.mx, header.my, header.mz)) if int(n) > 0]
    return tuple(size[::-1]) if len(size) == 3 and all(0 < s < math.inf for s in size) else None
