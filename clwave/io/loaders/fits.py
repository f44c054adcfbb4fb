"""FITS cubes (``.fits``, ``.fit``, ``.fts``, gzipped, and tile-compressed ``.fz``): spectral-line cubes of radio and
optical astronomy, their headers checked here before astropy reads them, their samples read by astropy
(``BSCALE``/``BZERO`` applied, ``BLANK`` as NaN), in pixel units, turned so that the view from +x (azimuth 0,
elevation 0) shows the sky as an astronomer sees it: north up, east left (docs/coordinates.md §1)."""

from __future__ import annotations

import gzip
import itertools
import math
import re
import warnings
from contextlib import contextmanager
from functools import partial

import numpy as np

from ...errors import FileFormatError
from .scaling import check_scaling
from .shared import GZIP_MAGIC, Declared, OnDemand, TimeSeries, as_array, check_declared_size, note, one_volume

FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fz", ".fits.gz", ".fit.gz", ".fts.gz")
_BLOCK = 2880  # FITS's block: each header and each HDU's data is padded to a multiple
#: each BITPIX's stored type
_STORED = {8: "u1", 16: "i2", 32: "i4", 64: "i8", -32: "f4", -64: "f8"}
_BITPIX = tuple(_STORED)
_VOLUME_AXES = "zyx"


def read_fits(path, chunks, fits=None, frame=None):
    """``(data, spacing, None)`` of a FITS file's cube, the first image HDU of 3 or more axes (a tile-compressed one
    too), as ``(z, y, x)``: latitude (Dec: north up, +z), longitude (RA: west, +y, so east is on the left as the sky is
    seen, facing -x) and the third axis (spectral, +x), by the celestial axes its WCS names; without them its axes 2,
    1 and 3 (pixel (1, 1) at the bottom left, as ds9 shows a plane).  A 4th axis of length 1 (Stokes) is dropped;
    of several planes (Stokes I, Q, U, V) the one ``frame`` picks (:meth:`.shared.TimeSeries.pick`), alone read.
    Spacing is in pixels: 1, but the celestial pixels' aspect (Dec over RA) along z."""
    index, header, dims = find_cube(path)
    if not path.name.lower().endswith(".gz"):  # astropy opens a gzip stream by reading it all: weighed first, below
        _check_opens(path, index)
    kept, planes = _kept_axes(path, dims)
    header = _image_header(path, index, header)
    order, flips, aspect = sky_axes(header, kept, path)
    stored = tuple(dims[a] for a in kept[::-1])  # numpy order: the kept FITS axes, the last first
    loaded, placed = tuple(stored[2 - a] for a in order), (aspect, (0.0, 0.0, 0.0), 0.0)
    picked = {}
    if planes is not None:  # the FITS axis of several planes: one read, as a file of that cube alone gives it
        name, step = _text(header, f"CTYPE{planes + 1}") or f"NAXIS{planes + 1}", _number(header, f"CDELT{planes + 1}")
        step = step if step is not None and 0 < step < math.inf else None
        series = TimeSeries(f"{path} holds {dims[planes]} planes along its axis {planes + 1} ({name}) beside its cube",
                            dims[::-1], samples(header), dims[planes], step,
                            _text(header, f"CUNIT{planes + 1}") if step else None, along=name)
        series.placed, series.loaded = placed, loaded
        picked = {planes: series.pick(frame, path)}
    else:
        one_volume(frame, path)
    source = OnDemand(partial(_read, str(path), index, len(dims), kept, picked), stored, samples(header),
                      chunks=(1,) + stored[1:])  # a plane is contiguous in the file
    try:
        data = as_array(source, chunks, fits=fits, path=path)  # a compressed file: whole (loaders.check_chunks)
    except Declared as declared:  # describe(): the volume's shape and pixel spacing, with no voxel read
        declared.loaded, declared.placed = loaded, placed
        raise
    data = data.transpose(tuple(2 - a for a in order))
    return data[tuple(slice(None, None, -1) if f else slice(None) for f in flips)], aspect, None


def find_cube(path):
    """``(index, header, dims)`` of the first image HDU of 3 or more axes in ``path``: its index, its header as stored
    (a tile-compressed image's table's), and its axes' lengths in FITS order (NAXIS1 first).  Each header on the way
    is checked before astropy reads it (astropy seeks past every HDU's declared data, and reads what it declares): its
    BITPIX, NAXIS and NAXISn, and the data it declares against what the file (or its gzip stream) holds; refused in
    one line where none holds a cube."""
    from astropy.io import fits

    zipped = path.name.lower().endswith(".gz")
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if zipped != (magic == GZIP_MAGIC):
        raise FileFormatError(f"{path} is not gzip-compressed, but its name ends in .gz: name it {path.name[:-3]}"
                              if zipped else f"{path} is gzip-compressed: name it {path.name}.gz")
    seen, offset = [], 0
    with (gzip.open if zipped else open)(path, "rb") as fh, _quiet():
        if not fh.read(80).startswith(b"SIMPLE  =                    T"):
            raise FileFormatError(f"{path} is not a FITS file (it does not begin with SIMPLE = T)")
        for index in itertools.count():
            fh.seek(offset)
            try:
                header = fits.Header.fromfile(fh)
            except EOFError:  # the end of the file, where the next HDU would begin
                break
            start = fh.tell()
            bitpix, axes = _checked(path, index, header, "")
            groups, heap = _whole(path, index, header, "GCOUNT", 1), _whole(path, index, header, "PCOUNT", 0)
            if min(groups, heap) < 0:
                raise FileFormatError(f"{path}: its HDU {index} has GCOUNT = {groups}, PCOUNT = {heap}; a count cannot "
                                      "be negative: the header is corrupt")
            nbytes = abs(bitpix) // 8 * groups * (heap + math.prod(axes))
            check_declared_size(path, start, nbytes * bool(axes), axes, gzip=zipped)
            tiled = header.get("ZIMAGE") is True
            if index == 0 or header.get("XTENSION") == "IMAGE" or tiled:
                dims = _checked(path, index, header, "Z")[1] if tiled else axes
                if len(dims) >= 3:
                    if min(dims) < 1:
                        raise FileFormatError(f"{path}: its HDU {index} declares {' x '.join(map(str, dims))} "
                                              "pixels; each axis needs at least one")
                    _check_tiles(path, index, header, len(dims) if tiled else 0)
                    _check_cards(path, index, header)
                    return index, header, dims
                seen.append(f"{index}: a {len(dims)}-D image" if dims else f"{index}: no data")
            else:
                seen.append(f"{index}: a {header.get('XTENSION', 'extension')}")
            offset = start + -(-nbytes * bool(axes) // _BLOCK) * _BLOCK
    raise FileFormatError(f"{path} holds no image of 3 or more axes (its HDUs: {'; '.join(seen)}); clwave reads "
                          "data cubes")


def samples(header) -> np.dtype:
    """The type of a cube's samples as astropy reads them, by its image ``header``, as FITS means them: BITPIX's; an
    integer type scaled (BSCALE, BZERO) or blanked (BLANK) becomes float (float32 from 8 and 16 bits, float64 from 32
    and 64), but where BZERO only makes it unsigned (BSCALE 1, BZERO 2^15 on 16 bits; astropy 8.0 fails on the signed
    bytes of BZERO -128, known-gaps §15)."""
    bitpix = header["BITPIX"]
    stored = np.dtype(_STORED[bitpix])
    if bitpix < 0:
        return stored
    bscale, bzero = header.get("BSCALE", 1), header.get("BZERO", 0)
    if bscale == 1 and bitpix > 8 and bzero == 2 ** (bitpix - 1):
        return np.dtype(f"u{bitpix // 8}")
    if bscale == 1 and bzero == 0 and "BLANK" not in header:
        return stored
    return np.dtype(np.float32 if bitpix <= 16 else np.float64)


def _image_header(path, index, header):
    """The header of a cube's image: its own, or a tile-compressed image's as astropy makes it of its table's (ZBITPIX,
    ZNAXISn...; opening it reads no pixel); its scaling (BSCALE, BZERO) refused in one line where it is no finite
    number, beyond float32's range (its voxels would be), or mapping every pixel to one value
    (:func:`.scaling.check_scaling`: a BSCALE of 0)."""
    if header.get("ZIMAGE") is True:
        with _opened(path) as hdul:
            header = hdul[index].header
    for key in ("BSCALE", "BZERO"):
        value = header.get(key)
        if value is None:
            continue
        if type(value) not in (int, float) or not math.isfinite(value):
            problem = "not a finite number"
        elif abs(value) > float(np.finfo(np.float32).max):  # a Python float: no cast of value to float32
            problem = "beyond float32's range (3.4e38), which clwave computes in"
        else:
            continue
        raise FileFormatError(f"{path}: its HDU {index} has {key} = {value!r}, {problem}; the header is corrupt")
    stored = _STORED.get(header.get("BITPIX"))
    if stored and ("BSCALE" in header or "BZERO" in header):
        check_scaling(f"{path}: its HDU {index}", ("BSCALE", "BZERO"), header.get("BSCALE", 1), header.get("BZERO", 0),
                      stored, samples(header))
    return header


def _checked(path, index, header, prefix):
    """``(BITPIX, [NAXIS1, ...])`` of an HDU's header (``prefix`` "Z": a tile-compressed image's ZBITPIX, ZNAXIS...),
    refused in one line where one is missing or not what FITS allows."""
    bitpix = header.get(prefix + "BITPIX")
    if type(bitpix) is not int or bitpix not in _BITPIX:
        raise FileFormatError(f"{path}: its HDU {index} has {prefix}BITPIX = {bitpix!r}, none FITS has "
                              f"({', '.join(map(str, _BITPIX))}); the header is corrupt")
    naxis = _whole(path, index, header, prefix + "NAXIS")
    if not 0 <= naxis <= 999:
        raise FileFormatError(f"{path}: its HDU {index} has {prefix}NAXIS = {naxis}, FITS allows 0 to 999; the header "
                              "is corrupt")
    axes = [_whole(path, index, header, f"{prefix}NAXIS{n}") for n in range(1, naxis + 1)]
    if axes and min(axes) < 0:
        raise FileFormatError(f"{path}: its HDU {index} declares {' x '.join(map(str, axes))} pixels "
                              f"({prefix}NAXISn); a length cannot be negative: the header is corrupt")
    return bitpix, axes


def _check_tiles(path, index, header, naxis):
    """Refuse a tile-compressed image's ZTILEn below 1 (of its ``naxis`` axes) in one line, before astropy divides
    by it."""
    for n in range(1, naxis + 1):
        if (tile := _whole(path, index, header, f"ZTILE{n}", 1)) < 1:
            raise FileFormatError(f"{path}: its HDU {index} has ZTILE{n} = {tile}; a tile needs at least one pixel: "
                                  "the header is corrupt")


#: the keywords of a cube's header that clwave, astropy's reading or its WCS read (astropy.wcs leaves a card it cannot
#: parse out without a word: an unparsable CDELT2 read as 1 degree, 1000 times CDELT1's 0.001)
_READ = re.compile(r"(Z?BITPIX|Z?NAXIS\d*|BSCALE|BZERO|BLANK|WCSAXES|C(TYPE|DELT|RPIX|RVAL|UNIT|ROTA)\d+|"
                   r"(PC|CD|PV|PS)\d+_\d+|LONPOLE|LATPOLE|RESTFRE?Q|EQUINOX|EPOCH|RADESYS|SPECSYS)")


def _check_cards(path, index, header):
    """Refuse a card of ``header`` (HDU ``index``) that clwave reads (:data:`_READ`) where astropy cannot parse it or
    where it is given twice with different values (``header.get`` took the first, astropy's section another)."""
    from astropy.io.fits.verify import VerifyError

    values = {}
    for card in header.cards:
        if not _READ.fullmatch(card.keyword):
            continue
        try:
            value = card.value
        except VerifyError:
            raise FileFormatError(f"{path}: its HDU {index}'s card {card.keyword} cannot be parsed (FITS's fixed "
                                  "format); the header is corrupt: correct the card") from None
        if values.setdefault(card.keyword, value) != value:
            raise FileFormatError(f"{path}: its HDU {index} has {card.keyword} twice, {values[card.keyword]!r} and "
                                  f"{value!r}; the header is corrupt: keep the true one")


def _whole(path, index, header, key, default=None):
    """An integer keyword of ``header`` (``default`` where it is missing; None: required)."""
    value = header.get(key, default)
    if value is None:
        raise FileFormatError(f"{path}: its HDU {index} has no {key}; the header is corrupt")
    if type(value) is not int:
        raise FileFormatError(f"{path}: its HDU {index} has {key} = {value!r}, not an integer; the header is corrupt")
    return value


def _kept_axes(path, dims):
    """``(kept, planes)``: the FITS axes (0-based) read as the volume's three, 1 and 2 and the first after them longer
    than 1 (else 3), and the one other axis longer than 1 whose planes ``frame=`` picks from (Stokes I, Q, U, V), or
    None; every other is of length 1 (a Stokes axis of one plane), else the cube is refused."""
    third = next((a for a in range(2, len(dims)) if dims[a] > 1), 2)
    many = [a for a in range(2, len(dims)) if a != third and dims[a] > 1]
    if len(many) > 1:
        axes = " and ".join(f"{a + 1} ({dims[a]})" for a in many)
        raise FileFormatError(f"{path} holds planes along its axes {axes} beside its cube; clwave reads one cube, "
                              "picking a plane along one axis only: write the planes you want to a file of their own "
                              "first (e.g. CASA's imsubimage)")
    return (0, 1, third), (many[0] if many else None)


def sky_axes(header, kept, path=None):
    """``(order, flips, spacing)`` of a cube whose FITS axes ``kept`` are read: ``order[v]``, the position in ``kept``
    of the axis that becomes volume axis ``v`` (z, y, x); ``flips[v]`` whether it is reversed; ``spacing`` (dz, dy, dx)
    in pixels, the latitude's pixel over the longitude's along z.  By its WCS's celestial axes (astropy.wcs): latitude
    to z increasing north, longitude to y increasing west, the third axis to x (a grid turned on the sky by the pixel
    axes nearest, with a warning naming ``path`` where it is given); without them (or a WCS astropy cannot read, with
    that warning) axis 2 to z, 1 to y, 3 to x, unflipped."""
    from astropy.wcs import WCS

    plain = ((1, 0, 2), (False, False, False), (1.0, 1.0, 1.0))
    try:
        with _quiet():
            wcs = WCS(header)
    except Exception as exc:  # noqa: BLE001 - any WCS astropy cannot read: the pixel grid, with a warning
        if path is not None:
            note(f"{path}: its WCS is not read ({type(exc).__name__}: {str(exc).strip().splitlines()[-1][:120]}); its "
                 "planes are shown as stored, axis 1 to the right and 2 up")
        return plain
    lng, lat = wcs.wcs.lng, wcs.wcs.lat
    if lng < 0 or lat < 0:
        return plain
    steps = wcs.pixel_scale_matrix[:, list(kept)]  # world units a pixel along each kept axis
    along = {w: int(np.argmax(np.abs(steps[w]))) for w in (lng, lat)}
    if along[lng] == along[lat]:
        return plain
    third = ({0, 1, 2} - set(along.values())).pop()
    east, north = steps[lng, along[lng]], steps[lat, along[lat]]
    turned = float(np.degrees(np.arctan2(abs(steps[lat, along[lng]]), abs(north))))
    if turned > 0.01 and path is not None:
        note(f"{path}: its sky is turned {turned:.2f} degrees on its pixel grid (CROTA2, or its PC/CD matrix): shown "
             "on that grid, north along the pixel axis nearest to it")
    aspect = abs(north / east) if east and north and math.isfinite(north / east) else 1.0
    return (along[lat], along[lng], third), (bool(north < 0), bool(east > 0), False), (aspect, 1.0, 1.0)


def header_facts(path) -> dict:
    """``{"fits": ...}``, what ``clwave info`` says of a FITS cube beyond its volume: its HDU, its values' unit
    (``BUNIT``) and scaling, and each axis: its type, unit, length, step, and the volume axis it becomes."""
    index, header, dims = find_cube(path)
    kept, _ = _kept_axes(path, dims)
    header = _image_header(path, index, header)
    order, flips, _ = sky_axes(header, kept)
    axes = []
    for a, n in enumerate(dims, 1):
        where = kept.index(a - 1) if a - 1 in kept else None
        volume = None if where is None else _VOLUME_AXES[order.index(where)]
        axes.append(dict(type=_text(header, f"CTYPE{a}"), unit=_text(header, f"CUNIT{a}"), length=n,
                         step=_number(header, f"CDELT{a}"), axis=volume,
                         flipped=None if volume is None else flips[_VOLUME_AXES.index(volume)]))
    scaling = {k: _number(header, k) for k in ("BSCALE", "BZERO", "BLANK") if _number(header, k) is not None}
    return dict(fits=dict(hdu=index, name=_text(header, "EXTNAME") or ("PRIMARY" if index == 0 else None),
                          unit=_text(header, "BUNIT"), scaling=scaling, axes=axes))


def _text(header, key):
    value = header.get(key)
    return None if value is None else str(value).strip()


def _number(header, key):
    value = header.get(key)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


@contextmanager
def _quiet():
    """astropy's warnings kept quiet (a card it fixes, a BLANK of a float cube it ignores, a WCS keyword it corrects):
    the header is checked here, and what is read said by clwave (a chunk's reading too: the filter, shared by
    threads, at worst stays)."""
    from astropy.utils.exceptions import AstropyWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AstropyWarning)
        yield


@contextmanager
def _opened(path):
    """astropy's HDU list of ``path``, quiet (:func:`_quiet`)."""
    from astropy.io import fits

    with _quiet(), fits.open(path, lazy_load_hdus=True) as hdul:
        yield hdul


def _check_opens(path, index):
    """Refuse (one line) a file whose HDU ``index`` astropy cannot open, which each read of a chunk would, where
    ``clwave info`` reads no pixel: a card astropy requires that is not what FITS allows (``EXTEND = NaN``: "Empty or
    corrupt FITS file").  astropy reads the headers up to it alone."""
    try:
        with _opened(path) as hdul:
            hdul[index].header  # read: the HDU opened
    except (OSError, ValueError, TypeError, KeyError, IndexError) as exc:
        raise FileFormatError(f"{path}: astropy cannot open its HDU {index} ({exc}); a card astropy requires is not "
                              "what FITS allows (as EXTEND = NaN): correct the header") from None


def _read(path, index, naxis, kept, picked, key):
    """``key`` (of the kept axes, in numpy order) of a cube, read anew (the file opened for each chunk) by astropy's
    section, scaled (BSCALE, BZERO; BLANK as NaN), in this machine's byte order; the other axes' one plane (of length
    1, or ``picked``'s, {axis: plane}) read and taken away."""
    key = key if isinstance(key, tuple) and Ellipsis not in key else (slice(None),) * 3
    full = [slice(0, 1)] * naxis
    for a, k in picked.items():
        full[naxis - 1 - a] = slice(k, k + 1)
    for k, a in zip(key, kept[::-1]):
        full[naxis - 1 - a] = k
    full[-1] = slice(None)  # whole rows, cut after: astropy reads a block of them at once, a part of a row at a time
    with _opened(path) as hdul, np.errstate(over="ignore", invalid="ignore"):  # past float32: Volume names it
        data = np.asarray(hdul[index].section[tuple(full)])  # big-endian as stored, unless scaled
    data = data.reshape([n for i, n in enumerate(data.shape) if naxis - 1 - i in kept])[..., key[-1]]
    return data.astype(data.dtype.newbyteorder("="), copy=False)  # as samples() says: a .clw records "float32"
