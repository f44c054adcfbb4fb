"""The ``.clw`` file of a wavelet model (docs/model.md §6): a zip of ``.npy`` arrays holding a JSON
header, each channel group's kept positions as a bit mask (deflated) and its exact float32 values."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import ClwaveError, FileFormatError, InputError
from ..model.bspline import SplineWavelet, max_levels
from ..model.transform import band_layout
from ..model.wavelet import ChannelGroup, WaveletVolume
from .files import write_atomic

FILE_FORMAT = "clwave-wavelet-volume"
FILE_VERSION = 1


def write_clw(wv: WaveletVolume, path, overwrite=False) -> Path:
    """Write ``wv`` to ``path`` atomically; refuses to replace a file unless ``overwrite``."""
    header = dict(format=FILE_FORMAT, version=FILE_VERSION, shape=wv.shape,
                  spacing=wv.spacing, origin=wv.origin, levels=wv.levels,
                  channels=wv.channels, interpolate=wv.interpolate,
                  focus=None if wv.focus is None else [list(wv.focus[0]), wv.focus[1]],
                  transfer_function=wv.transfer_function, content=wv.content,
                  groups=[dict(wavelet=g.wavelet.order, channels=list(g.channels)) for g in wv.groups])
    arrays = {"header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)}
    if wv.content_mask is not None:
        arrays["content_mask"] = np.packbits(wv.content_mask)
    for gi, g in enumerate(wv.groups):
        stored = np.any(g.values != 0, axis=0)  # a zero coefficient adds nothing: it is not stored
        mask = np.zeros(g.total, dtype=bool)
        mask[g.all_positions()[stored]] = True
        arrays[f"mask{gi}"] = np.packbits(mask)
        arrays[f"values{gi}"] = np.ascontiguousarray(g.values[:, stored], dtype=np.float32)
    return write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays), overwrite)


DEFLATE_MAX_RATIO = 1032  # deflate cannot expand a byte into more than this: bounds what a member may hold
CHUNK = 1 << 24            # mask bytes unpacked at a time


def read_clw(path) -> WaveletVolume:
    """Read a ``.clw`` file written by :func:`write_clw`.

    The file is untrusted: its header is checked, and every member's declared size against the
    header and against what its compressed bytes can hold, before anything is decompressed or
    allocated; the positions come from the mask chunk by chunk (memory of the kept coefficients).
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{path} does not exist or is not a file")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as npz:
            if "header" not in npz.files:
                raise ValueError("no header member")
            _check_member(npz, "header", 1 << 20)
            header = json.loads(bytes(npz["header"]).decode())
            if header.get("format") != FILE_FORMAT or header.get("version") != FILE_VERSION:
                raise FileFormatError(f"{path} is not a clwave v{FILE_VERSION} wavelet volume file (format "
                                      f"{header.get('format')!r}, version {header.get('version')!r})")
            shape, levels, channels, groups_header = _checked_header(header)
            groups = []
            for gi, gh in enumerate(groups_header):
                wav = SplineWavelet(gh["wavelet"])
                bands = band_layout(wav, shape, levels)
                total = bands[-1].start + bands[-1].size
                _check_member(npz, f"mask{gi}", -(-total // 8))
                positions = _positions(npz[f"mask{gi}"], total)
                _check_member(npz, f"values{gi}", 4 * len(gh["channels"]) * len(positions))
                values = npz[f"values{gi}"]
                if values.shape != (len(gh["channels"]), len(positions)) or values.dtype != np.float32:
                    raise ValueError(f"group {gi}: values {values.shape} do not match the index mask")
                if not np.all(np.isfinite(values)):
                    raise ValueError(f"group {gi} holds non-finite values")
                groups.append(ChannelGroup(wav, gh["channels"], bands,
                                           None if len(positions) == total else positions, values))
            mask = None
            if "content_mask" in npz.files:
                _check_member(npz, "content_mask", -(-int(np.prod(shape)) // 8))
                packed = npz["content_mask"]
                if len(packed) != -(-int(np.prod(shape)) // 8):
                    raise ValueError(f"the content mask has {len(packed)} bytes for {int(np.prod(shape))} voxels")
                mask = np.unpackbits(packed, count=int(np.prod(shape))).astype(bool).reshape(shape)
    except ClwaveError:
        raise
    except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"cannot read {path} as a .clw file ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); "
                              "the file may be truncated or corrupt") from None
    focus = header["focus"]
    try:
        return WaveletVolume(shape, header["spacing"], header["origin"], levels, groups, channels,
                             interpolate=bool(header["interpolate"]),
                             focus=None if focus is None else (tuple(focus[0]), float(focus[1])),
                             transfer_function=header["transfer_function"], content=header.get("content"),
                             content_mask=mask)
    except (KeyError, ValueError, TypeError, InputError) as exc:
        raise FileFormatError(f"{path} is inconsistent ({exc}); the file may be corrupt") from None


def _checked_header(header) -> tuple:
    """``(shape, levels, channels, groups)`` of a header, each checked (ValueError names what is wrong)."""
    shape = header.get("shape")
    if not (isinstance(shape, list) and len(shape) == 3 and all(isinstance(n, int) and 2 <= n <= 1 << 20
                                                                 for n in shape)):
        raise ValueError(f"shape {shape!r} is not three whole numbers from 2 to 2^20")
    shape = tuple(shape)
    for name, positive in (("spacing", True), ("origin", False)):
        value = header.get(name)
        if not (isinstance(value, list) and len(value) == 3 and all(isinstance(v, (int, float)) for v in value)
                and np.all(np.isfinite(value)) and (not positive or min(value) > 0)):
            raise ValueError(f"{name} {value!r} is not three finite{' positive' if positive else ''} numbers")
    levels, channels = header.get("levels"), header.get("channels")
    if not (isinstance(levels, int) and 0 <= levels <= max_levels(shape)):
        raise ValueError(f"levels {levels!r} is not possible for shape {shape}")
    if not (isinstance(channels, int) and 1 <= channels <= 4):
        raise ValueError(f"channels {channels!r} is not 1 to 4")
    groups = header.get("groups")
    if not (isinstance(groups, list) and groups):
        raise ValueError("the file has no channel groups")
    seen = []
    for g in groups:
        if not (isinstance(g, dict) and g.get("wavelet") in (1, 2, 3, 4) and isinstance(g.get("channels"), list)):
            raise ValueError(f"channel group {g!r} is not a wavelet order 1-4 with a list of channels")
        seen += g["channels"]
    if sorted(seen) != list(range(channels)):
        raise ValueError(f"the groups hold channels {sorted(seen)}, not each of the {channels} once")
    return shape, levels, channels, groups


def _check_member(npz, name, expected_bytes):
    """Refuse a member that is missing, declares more than ``expected_bytes`` (plus the .npy header), or
    more than its compressed bytes can hold: nothing is decompressed beyond what the header allows."""
    try:
        info = npz.zip.getinfo(name + ".npy")
    except KeyError:
        raise ValueError(f"member {name} is missing") from None
    if info.file_size > expected_bytes + 4096 or info.file_size > DEFLATE_MAX_RATIO * info.compress_size + 4096:
        raise ValueError(f"member {name} declares {info.file_size} bytes where the header allows {expected_bytes}")


def _positions(packed, total) -> np.ndarray:
    """The set positions of a packed bit mask of ``total`` bits, unpacked a chunk at a time."""
    if len(packed) != -(-total // 8):
        raise ValueError(f"the index mask has {len(packed)} bytes for {total} positions")
    parts = [np.flatnonzero(np.unpackbits(packed[i:i + CHUNK], count=min(8 * CHUNK, total - 8 * i))) + 8 * i
             for i in range(0, len(packed), CHUNK)]
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)
