"""Headerless ``.raw`` files and ``.npy`` files: memory maps, read whole or chunk by chunk."""

from __future__ import annotations

import math
import os
from functools import partial

import numpy as np

from ...errors import FileFormatError, InputError
from .shared import OnDemand, as_array, check_declared_size


def read_raw(path, shape, dtype, byte_order, chunks, fits=None):
    """Headerless samples, C order (x fastest); the file size must match exactly."""
    if shape is None or dtype is None:
        raise InputError(f"{path.name}: a .raw file has no header; give shape=(Z, Y, X) or (Z, Y, X, C) and dtype= "
                         "(e.g. 'uint16')", cli=f"{path.name}: a .raw file has no header; give --shape Z,Y,X (or "
                                                "Z,Y,X,C) and --dtype (e.g. uint16)")
    try:
        shape = tuple(int(n) for n in shape)
        dt = np.dtype(dtype)
    except (TypeError, ValueError):
        raise InputError(f"bad shape={shape!r} or dtype={dtype!r} for {path.name}; give shape=(Z, Y, X) and a numpy "
                         f"dtype such as 'uint16'", cli=f"bad --dtype {dtype} for {path.name}; give a numpy dtype "
                                                        f"such as uint16, float32 or >i2") from None
    if len(shape) not in (3, 4) or min(shape) < 1:
        raise InputError(f"shape={shape} must be (Z, Y, X) or (Z, Y, X, C) with positive sizes",
                         cli=f"--shape {','.join(map(str, shape))} must be Z,Y,X or Z,Y,X,C with positive sizes")
    if byte_order not in (None, "<", ">"):
        raise InputError(f"byte_order={byte_order!r} must be '<' (little endian) or '>' "
                         "(big endian)")
    if byte_order is not None:
        dt = dt.newbyteorder(byte_order)
    expected = math.prod(shape) * dt.itemsize  # Python's ints: numpy's wrap at 2^64
    actual = os.path.getsize(path)
    if actual != expected:
        values = " x ".join(map(str, shape))
        needs = f"{path} has {actual:,} bytes but {values} values of {dt.name} need {expected:,} bytes"
        raise FileFormatError(f"{needs}; check shape= and dtype=, or the file is truncated",
                              cli=f"{needs}; check --shape and --dtype, or the file is truncated")
    return as_array(OnDemand(partial(read_memmap, str(path), dt, shape, 0, "C"), shape, dt), chunks, fits=fits,
                    path=path), None, None


def read_npy(path, chunks, fits=None):
    """A .npy file, memory-mapped (C or Fortran order); a header declaring more than the file holds is refused."""
    fmt = np.lib.format
    with open(path, "rb") as fh:
        version = fmt.read_magic(fh)
        shape, _, dtype = (fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0)(fh)
        check_declared_size(path, fh.tell(), math.prod(shape) * dtype.itemsize, shape, gzip=False)
    if dtype.hasobject:
        raise FileFormatError(f"{path} is a NumPy array of Python objects ({dtype}), not of numbers: not a volume "
                              f"clwave reads; save it as numbers, e.g. np.save(path, volume.astype(np.float32))")
    mapped = np.load(path, mmap_mode="r", allow_pickle=False)  # reads the header only
    order = "F" if mapped.flags.f_contiguous and not mapped.flags.c_contiguous else "C"
    return as_array(OnDemand(partial(read_memmap, str(path), mapped.dtype, mapped.shape, mapped.offset, order),
                            mapped.shape, mapped.dtype), chunks, fits=fits, path=path)


def read_memmap(path, dtype, shape, offset, order, index):
    return np.array(np.memmap(path, dtype, "r", offset, shape, order)[index])
