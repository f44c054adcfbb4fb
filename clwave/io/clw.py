"""The ``.clw`` file of a wavelet model (docs/model.md §6): a zip of ``.npy`` arrays holding a JSON
header, each channel group's kept positions as a bit mask (deflated) and its exact float32 values."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from ..model.bspline import SplineWavelet
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


def read_clw(path) -> WaveletVolume:
    """Read a ``.clw`` file written by :func:`write_clw`."""
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{path} does not exist or is not a file")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as npz:
            header = json.loads(bytes(npz["header"]).decode())
            arrays = {k: npz[k] for k in npz.files if k != "header"}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"cannot read {path} as a .clw file ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); "
                              "the file may be truncated or corrupt") from None
    if header.get("format") != FILE_FORMAT or header.get("version") != FILE_VERSION:
        raise FileFormatError(f"{path} is not a clwave v{FILE_VERSION} wavelet volume file")
    try:
        shape, levels = tuple(header["shape"]), int(header["levels"])
        groups = []
        for gi, gh in enumerate(header["groups"]):
            wav = SplineWavelet(int(gh["wavelet"]))
            bands = band_layout(wav, shape, levels)
            total = bands[-1].start + bands[-1].size
            mask = np.unpackbits(arrays[f"mask{gi}"], count=total).astype(bool)
            values = arrays[f"values{gi}"]
            if values.shape != (len(gh["channels"]), int(mask.sum())) or values.dtype != np.float32:
                raise ValueError(f"group {gi}: values {values.shape} do not match the index mask")
            positions = None if mask.all() else np.flatnonzero(mask)
            groups.append(ChannelGroup(wav, gh["channels"], bands, positions, values))
        focus = header["focus"]
        return WaveletVolume(shape, header["spacing"], header["origin"], levels, groups, header["channels"],
                   interpolate=header["interpolate"],
                   focus=None if focus is None else (tuple(focus[0]), float(focus[1])),
                   transfer_function=header["transfer_function"], content=header.get("content"),
                   content_mask=_content_mask(arrays, shape))
    except (KeyError, ValueError, TypeError, InputError) as exc:
        raise FileFormatError(f"{path} is inconsistent ({exc}); the file may be corrupt") from None


def _content_mask(arrays, shape):
    """The source volume's non-zero voxels (:attr:`WaveletVolume.content_mask`), where the file has them."""
    if "content_mask" not in arrays:
        return None
    return np.unpackbits(arrays["content_mask"], count=int(np.prod(shape))).astype(bool).reshape(shape)
