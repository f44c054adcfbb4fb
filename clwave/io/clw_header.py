"""The checks of a ``.clw`` file's header and members (docs/chunked.md §4), made before anything is allocated: the
file is untrusted, and any failure is a ValueError naming what is wrong (:func:`clwave.io.clw.open_clw` turns it
into one line naming the file)."""

from __future__ import annotations

import json
import zlib

import numpy as np

from ..errors import FileFormatError, InputError
from .images import UNIT_METRES
from ..model.bspline import WAVELET_ORDERS, max_levels
from ..model.volume import check_modality, check_provenance, frame_problem
from ..model.transfer import TransferFunction

FILE_FORMAT = "clwave-wavelet-volume"
FILE_VERSION = 2
MAX_HEADER = 1 << 20


def parsed_header(h5, path) -> dict:
    """The JSON header of an open ``.clw`` (a format or version not this clwave's: FileFormatError)."""
    fmt, version = h5.attrs.get("format"), h5.attrs.get("version")
    version = version.item() if isinstance(version, np.generic) else version
    if fmt != FILE_FORMAT:
        raise FileFormatError(f"{path} is an HDF5 file but not a clwave wavelet volume (format {fmt!r})")
    if version != FILE_VERSION:
        raise FileFormatError(f"{path} is a .clw file of format version {version!r}; this clwave reads version "
                              f"{FILE_VERSION}: use the clwave that wrote it, or compress the volume again")
    text = h5.attrs.get("header")
    if not isinstance(text, str) or len(text) > MAX_HEADER:
        raise ValueError("the header is missing or too long")
    if h5.attrs.get("header_crc32") != zlib.crc32(text.encode()):  # HDF5 checksums datasets, not attributes
        raise ValueError("the header does not match its checksum")
    header = json.loads(text)
    if not isinstance(header, dict):
        raise ValueError(f"the header is a JSON {type(header).__name__}, not an object")
    return header


def checked_values(dataset, shape):
    """A group's values: float32, or int32 with a finite positive scalar ``step`` attribute (returned)."""
    import h5py

    if not (isinstance(dataset, h5py.Dataset) and "step" in dataset.attrs):
        check_dataset(dataset, shape, np.float32)
        return None
    stored = dataset.attrs.get_id("step")  # its shape and type before its value: an array is not read
    if stored.shape != () or stored.dtype.kind != "f":
        raise ValueError(f"member {dataset.name} has a quantisation step of shape {stored.shape} and type "
                         f"{stored.dtype}, not one number")
    step = dataset.attrs["step"]
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"member {dataset.name} has a quantisation step {step!r}, not one finite number > 0")
    check_dataset(dataset, shape, np.int32)
    return float(step)


def member_rows(member, ndim) -> int:
    """The length of a member's first axis where it is a dataset of ``ndim`` axes, else -1 (a missing member, a group,
    another shape: :func:`check_dataset` then refuses it by name)."""
    import h5py

    return member.shape[0] if isinstance(member, h5py.Dataset) and member.ndim == ndim else -1


def check_dataset(dataset, shape, dtype):
    """Refuse a member that is missing, of another shape or type, or chunked oddly (a decompression bomb
    cannot hide in a chunk larger than the file allows)."""
    import h5py

    if not isinstance(dataset, h5py.Dataset):
        raise ValueError("a member is missing or not a dataset")
    if dataset.shape != tuple(shape) or dataset.dtype != dtype:
        raise ValueError(f"member {dataset.name} is {dataset.shape} {dataset.dtype}, expected {tuple(shape)} "
                         f"{np.dtype(dtype)}")
    if dataset.chunks is not None and int(np.prod(dataset.chunks)) * dataset.dtype.itemsize > 1 << 26:
        raise ValueError(f"member {dataset.name} has chunks of {dataset.chunks}, larger than a .clw writes")
    # a .clw writes every chunk: a member whose chunks are not all stored would have the reader allocate
    # for data the file does not hold
    stored, whole = ((dataset.id.get_num_chunks(), int(np.prod([-(-n // c) for n, c in zip(shape, dataset.chunks)])))
                     if dataset.chunks is not None else (dataset.id.get_storage_size(), dataset.nbytes))
    if stored < whole:
        raise ValueError(f"member {dataset.name} stores {stored} of its {whole} "
                         f"{'chunks' if dataset.chunks is not None else 'bytes'}")


def checked_header(header) -> tuple:
    """``(shape, levels, channels, groups)`` of a header, each checked, and the rest of the header as the model opened
    from it uses it (:func:`check_properties`); ValueError names what is wrong."""
    shape = header.get("shape")
    if not (isinstance(shape, list) and len(shape) == 3 and all(_whole(n) and 2 <= n <= 1 << 20 for n in shape)):
        raise ValueError(f"shape {shape!r} is not three whole numbers from 2 to 2^20")
    shape = tuple(shape)
    for name, positive in (("spacing", True), ("origin", False)):
        value = header.get(name)
        if not (_numbers(value, 3) and (not positive or min(value) > 0)):
            raise ValueError(f"{name} {value!r} is not three finite{' positive' if positive else ''} numbers")
    problem = frame_problem(shape, header["spacing"], header["origin"])
    if problem:
        raise ValueError(problem[0])
    subtracted = header.get("offset", 0.0)  # the value subtracted (its key of old); absent in older files: none
    if not _numbers([subtracted], 1):
        raise ValueError(f"offset {subtracted!r} (the value subtracted) is not one finite number")
    obliquity = header.get("obliquity", 0.0)  # absent in older files: read as axis-aligned
    if not (_numbers([obliquity], 1) and 0 <= obliquity <= 90):
        raise ValueError(f"obliquity {obliquity!r} is not one number of degrees from 0 to 90")
    unit = header.get("unit")  # the world unit; absent in older files (and None): unknown
    if unit is not None and unit not in UNIT_METRES:
        raise ValueError(f"unit {unit!r} is not one of {', '.join(UNIT_METRES)}")
    if header.get("photo", False) not in (False, True):  # absent in older files: classified where RGBA
        raise ValueError(f"photo {header['photo']!r} is not true or false")
    try:  # absent in older files (and None): not known
        check_provenance(header.get("provenance"))
        header["modality"] = check_modality(header.get("modality"))  # a name alone ("CT") as a Volume holds it
    except InputError as exc:  # said as the file's fault
        raise ValueError(str(exc)) from None
    levels, channels = header.get("levels"), header.get("channels")
    if not (_whole(levels) and 0 <= levels <= max_levels(shape)):
        raise ValueError(f"levels {levels!r} is not possible for shape {shape}")
    if not (_whole(channels) and 1 <= channels <= 4):
        raise ValueError(f"channels {channels!r} is not 1 to 4")
    groups = header.get("groups")
    if not (isinstance(groups, list) and groups):
        raise ValueError("the file has no channel groups")
    seen = []
    for g in groups:
        orders = sorted(WAVELET_ORDERS.values())
        if not (isinstance(g, dict) and _whole(g.get("wavelet")) and g["wavelet"] in orders
                and isinstance(g.get("channels"), list) and all(_whole(c) for c in g["channels"])):
            raise ValueError(f"channel group {g!r} is not a wavelet order {orders} with a list of channel numbers")
        seen += g["channels"]
    if sorted(seen) != list(range(channels)):
        raise ValueError(f"the groups hold channels {sorted(seen)}, not each of the {channels} once")
    check_properties(header, shape)
    return shape, levels, channels, groups


def check_properties(header, shape):
    """The header's interpolation, focus, content box (inside the volume's box, as a writer finds it), value range,
    model error, noise level and transfer function, checked as the model opened from the file uses them (``clwave
    info`` shows them); ``shape``, spacing and origin checked already: ValueError names what is wrong."""
    interpolate, focus, content = header.get("interpolate"), header.get("focus"), header.get("content")
    if not isinstance(interpolate, bool):
        raise ValueError(f"interpolate {interpolate!r} is not true or false")
    if focus is not None and not (isinstance(focus, list) and len(focus) == 2 and _numbers(focus[0], 3)
                                  and _numbers(focus[1:], 1) and focus[1] > 0):
        raise ValueError(f"focus {focus!r} is not [[x, y, z], sigma]: a finite centre and a sigma > 0")
    if content is not None and not (isinstance(content, list) and len(content) == 2
                                    and all(_numbers(corner, 3) for corner in content)
                                    and np.all(np.less(*content))):  # whole voxels: never empty
        raise ValueError(f"content {content!r} is not two corners [x, y, z] of finite numbers, low below high")
    if content is not None:  # the volume's box: its voxels' boxes about their centres (Volume.content_box)
        spacing = np.array(header["spacing"][::-1], float)
        half = np.array(shape[::-1]) * spacing / 2
        slack = spacing / 2  # rounding: half a voxel, far above it
        centre = np.array(header["origin"])
        if np.any(np.array(content[0]) < centre - half - slack) or np.any(np.array(content[1]) > centre + half + slack):
            raise ValueError(f"content {content!r} reaches outside the volume's box {(centre - half).tolist()} to "
                             f"{(centre + half).tolist()}")
        # whole voxels: a header whose spacing changed alone has the renderers fit a box of other voxels
        faces = (np.array(content) - (centre - half)) / spacing
        rounding = 1e-3 + 16 * np.finfo(float).eps * (np.abs(content) + np.abs(centre) + half).max() / spacing
        if np.any(np.abs(faces - np.round(faces)) > rounding) or np.any(faces[1] - faces[0] < 1 - rounding):
            raise ValueError(f"content {content!r} does not lie on the faces of the volume's voxels (spacing "
                             f"{spacing.tolist()} about {centre.tolist()})")
    value_range = header.get("value_range")  # absent in older files: not known (no clamp, docs/raytracing.md §10)
    if value_range is not None and not (_numbers(value_range, 2) and value_range[0] <= value_range[1]):
        raise ValueError(f"value_range {value_range!r} is not two finite numbers [min, max], min <= max")
    error = header.get("model_error")  # absent: not recorded (a file of before session 20, or not measured)
    if error is not None and not (_numbers([error], 1) and error >= 0):
        raise ValueError(f"model_error {error!r} is not a finite number >= 0")
    sigma = header.get("noise_sigma")  # absent: not recorded (before the twenty-first session, or not measured)
    if sigma is not None and not (isinstance(sigma, list) and len(sigma) == header["channels"] and all(
            s is None or (_numbers([s], 1) and s >= 0) for s in sigma)):
        raise ValueError(f"noise_sigma {sigma!r} is not a number >= 0 (or null) per channel")
    tf = header.get("transfer_function")
    if tf is not None:
        try:
            TransferFunction.from_dict(tf)
        except (TypeError, ValueError) as exc:  # InputError is a ValueError: said here as the file's fault
            raise ValueError(f"its transfer function is not valid: {exc}") from None


def _whole(value) -> bool:
    """Whether ``value`` is a JSON whole number (an int, not a boolean or a float)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _numbers(value, count) -> bool:
    """Whether ``value`` is a JSON list of ``count`` finite numbers (no booleans)."""
    return (isinstance(value, list) and len(value) == count
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            and bool(np.all(np.isfinite(value))))
