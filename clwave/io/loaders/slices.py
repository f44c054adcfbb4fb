"""Folders of 2-D slices, one file a slice (TIFF, PNG or JPEG: e.g. a cryosection's photographs), stacked along z
in natural name order (docs/coordinates.md §1)."""

from __future__ import annotations

from functools import partial

import numpy as np

from ...errors import FileFormatError
from .shared import OnDemand, as_array, by_size, check_slice, check_whole, folder_files, no_spacing, read_slices, \
    reading
from .tiff import TIFF_SUFFIXES, read_tiff

#: the slice formats a folder may hold (one of them), by file name suffix
SLICE_SUFFIXES = {"TIFF": TIFF_SUFFIXES, "PNG": (".png",), "JPEG": (".jpg", ".jpeg")}
#: Pillow's modes of the images read as they are: grey (1, 8 or 16 bit), grey + alpha, a palette (read as RGB or
#: RGBA), RGB and RGBA; others (CMYK, YCbCr, 32-bit) hold no colour clwave models as it is stored
_IMAGE_MODES = ("1", "L", "LA", "I;16", "I;16B", "P", "RGB", "RGBA")
#: PNG colour types with an alpha or colour sample, which Pillow reads as 8 bits even where the file stores 16
_PNG_COLOUR_TYPES = {2: "RGB", 4: "grey + alpha", 6: "RGBA"}


def slice_files(folder):
    """``(format, files)`` of a folder of slices in natural name order (``slice2`` before ``slice10``), or
    ``(None, [])`` where it holds none; a folder of slices in several formats is refused."""
    found = {name: [p for p in folder_files(folder) if p.suffix.lower() in suffixes]
             for name, suffixes in SLICE_SUFFIXES.items()}
    found = {name: files for name, files in found.items() if files}
    if len(found) > 1:
        raise FileFormatError(f"folder {folder} mixes slices of {' and '.join(found)} "
                              f"(e.g. {', '.join(files[0].name for files in found.values())}); a volume's slices are "
                              f"of one format: move the others out of the folder")
    return next(iter(found.items()), (None, []))


def read_slice_folder(folder, progress_bar, fits=None, chunks=False, warn_spacing=False):
    """One 2-D image per file, stacked along z in natural name order; all of one size, mode and sample type.  Slices
    hold no spacing: 1, 1, 1 with a warning where ``warn_spacing`` (none was given).  TIFF slices may be read chunk
    by chunk (``chunks``, :func:`.shared.as_array`'s; None: by size): each chunk's files read by tifffile when it is
    computed (:func:`_tiff_slices`), the stack weighed after its first slice."""
    kind, files = slice_files(folder)
    _check_headers(files, kind)
    if warn_spacing:
        no_spacing(folder)
    if kind == "TIFF":
        with reading(files[0]):
            first = _tiff_slice(files[0])
        shape = (len(files),) + first.shape
        if by_size(chunks, shape) is not False:
            source = OnDemand(partial(_tiff_slices, tuple(map(str, files)), first.shape, first.dtype), shape,
                              first.dtype, (1,) + first.shape)
            return as_array(source, chunks, path=folder)
        return read_slices(files, lambda path: first if path == files[0] else _tiff_slice(path), "reading TIFF slices",
                           progress_bar, fits)
    return read_slices(files, _image_slice, f"reading {kind} slices", progress_bar, fits)


def _check_headers(files, kind):
    """Refuse a folder whose slices' headers do not all declare the first's shape and sample type
    (:func:`.shared.check_slice`), read by their headers alone: ``clwave info``, which decodes the first slice only,
    refuses the folder the read would, and the read before it reads the slices."""
    import imageio.v3 as iio
    from tifffile import TiffFile

    first = None
    for path in files:
        with reading(path):
            if kind == "TIFF":
                with TiffFile(path) as tif:
                    head = tif.pages.first
            else:
                head = iio.improps(path, plugin="pillow")
        if first is None:
            first = head
        else:
            check_slice(path, head, first.shape, first.dtype, files[0])


def _tiff_slices(files, shape, dtype, index):
    """The slices of ``index``'s z range, ``index`` of each: every one of the ``shape`` and ``dtype`` of the first,
    as a whole read's (:func:`.shared.read_slices`)."""
    out = []
    for path in files[index[0]]:
        with reading(path):
            image = _tiff_slice(path)
        check_slice(path, image, shape, dtype, files[0])
        out.append(image[index[1:]])
    return np.stack(out)


def _tiff_slice(path):
    pages = read_tiff(path, stack=False)[0]
    if len(pages) != 1:
        raise FileFormatError(f"{path} holds {len(pages)} pages, but a folder of TIFF "
                              "slices needs one 2-D image per file")
    return pages[0]


def _image_slice(path):
    """A PNG or JPEG slice through imageio's Pillow plugin, the file opened once: its mode and (a PNG's) bit depth
    checked and its declared size weighed before it is decoded."""
    import imageio.v3 as iio

    with open(path, "rb") as fh:
        head = fh.read(26)  # a PNG's signature and IHDR chunk, whose bit depth Pillow keeps no public record of
        fh.seek(0)
        with iio.imopen(fh, "r", plugin="pillow") as image:
            mode = image.metadata().get("mode")
            if mode not in _IMAGE_MODES:
                raise FileFormatError(f"{path} is a {mode} image; clwave reads grey, RGB and RGBA slices: convert "
                                      f"it, e.g. PIL.Image.open(path).convert('RGB').save(path)")
            if head[:8] == b"\x89PNG\r\n\x1a\n" and head[24] == 16 and head[25] in _PNG_COLOUR_TYPES:
                raise FileFormatError(f"{path} is a 16-bit {_PNG_COLOUR_TYPES[head[25]]} PNG, which Pillow reads as "
                                      f"8 bits; save the slices as 16-bit TIFF (tifffile.imwrite(path, image)) to "
                                      f"keep all 16")
            props = image.properties()
            check_whole(path, (1,) + props.shape, props.dtype)
            return image.read()
