"""The host side of the host-kernel boundary: each kernel's arguments declared once, by name.

A :class:`Kernel` lists a kernel's arguments in the order of its OpenCL signature, each with
its type: a NumPy scalar type, a ``pyopencl.cltypes`` vector type (given any sequence of up to
its length, zero-padded), :data:`BUFFER`, or :data:`REAL` (the build's precision).
Launches name every argument (``KERNEL(ks, queue, (n,), None, n=n, first=0, ...)``), so a
renderer and the kernel's test call the same declaration and an argument cannot slip position.
Constants that both sides use come from :mod:`clwave.device.constants` as build defines.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

BUFFER = "buffer"  #: a ``pyopencl`` buffer, or an array whose ``.data`` is one
REAL = "real"      #: the kernel's ``real``: float32 or float64 by the build (``real_type=`` at launch)


class Kernel:
    """One kernel's name and its ``(argument name, type)`` pairs in signature order."""

    def __init__(self, name: str, *args: tuple):
        self.name = name
        self.args = tuple(args)
        self.names = tuple(a for a, _ in args)
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"{name}: an argument is declared twice")

    def __repr__(self):
        return f"Kernel({self.name}: {', '.join(self.names)})"

    def arguments(self, tables: Mapping | None = None, real_type=np.float32, **values) -> list:
        """The positional arguments from ``values`` by name; missing names are taken from
        ``tables`` (a mapping that may hold more), so a view's uploaded tables pass as one."""
        unknown = set(values) - set(self.names)
        if unknown:
            raise TypeError(f"{self.name} takes no argument {', '.join(sorted(unknown))}")
        out = []
        for name, kind in self.args:
            if name in values:
                value = values[name]
            elif tables is not None and name in tables:
                value = tables[name]
            else:
                raise TypeError(f"{self.name}: argument {name} is missing")
            if kind == BUFFER:
                out.append(getattr(value, "data", value))
            elif kind == REAL:
                out.append(np.dtype(real_type).type(value))
            elif isinstance(kind, np.dtype) and kind.fields:  # an OpenCL vector type (cltypes)
                out.append(_vector(kind, value))
            else:
                out.append(np.dtype(kind).type(value))
        return out

    def __call__(self, kernels, queue, global_size, local_size, tables: Mapping | None = None, real_type=np.float32,
                 global_offset=None, **values):
        """Launch the kernel of this name from ``kernels`` (a :class:`~clwave.device.programs.KernelSet`)."""
        args = self.arguments(tables, real_type, **values)
        return kernels[self.name](queue, global_size, local_size, *args, global_offset=global_offset)


LAUNCH_SECONDS = 0.2  #: what one launch of a long 2-D kernel aims at: Ctrl-C waits for the launch running


def in_row_bands(queue, launch, global_size, local_size):
    """``launch(global_size, global_offset)`` over bands of rows (axis 1) of a 2-D range, the queue finished
    after each, so that Python takes a KeyboardInterrupt within about :data:`LAUNCH_SECONDS` however long
    the whole is; each band sized from the rate of the last (whole work-groups of rows), at most twice
    as tall as it (empty rows are fast, and say little of the next ones)."""
    step, total = local_size[1], global_size[1]
    row, rows = 0, step
    while row < total:
        band = min(rows, total - row)
        start = time.perf_counter()
        launch((global_size[0], band), (0, row))
        queue.finish()
        row += band
        rate = band / max(time.perf_counter() - start, 1e-6)
        rows = max(step, min(2 * band, int(rate * LAUNCH_SECONDS) // step * step))


def _vector(kind: np.dtype, value):
    """An OpenCL vector of ``kind`` from a sequence of at most its length (zero-padded), or as given."""
    if getattr(value, "dtype", None) == kind:
        return value
    size, real = len(kind.names), kind.fields["s0"][0].kind == "f"
    items = [float(v) if real else int(v) for v in value]
    if len(items) > size:
        raise TypeError(f"{len(items)} values do not fit a {size}-vector")
    return np.array(tuple(items + [0] * (size - len(items))), dtype=kind)  # 0-d, as pyopencl.cltypes makes
