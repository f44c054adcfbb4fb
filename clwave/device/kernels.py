"""The host side of the host-kernel boundary: each kernel's arguments declared once, by name.

A :class:`Kernel` lists a kernel's arguments in the order of its OpenCL signature, each with
its type: a NumPy scalar type, a ``pyopencl.cltypes`` vector type (given any sequence of up to
its length, zero-padded), :data:`BUFFER`, or :data:`REAL` (the build's precision).
Launches name every argument (``KERNEL(ks, queue, (n,), None, n=n, first=0, ...)``), so a
renderer and the kernel's test call the same declaration and an argument cannot slip position.
Constants that both sides use come from :mod:`clwave.device.constants` as build defines.
"""

from __future__ import annotations

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
                 **values):
        """Launch the kernel of this name from ``kernels`` (a :class:`~clwave.device.programs.KernelSet`)."""
        args = self.arguments(tables, real_type, **values)
        return kernels[self.name](queue, global_size, local_size, *args)


def _vector(kind: np.dtype, value):
    """An OpenCL vector of ``kind`` from a sequence of at most its length (zero-padded), or as given."""
    if getattr(value, "dtype", None) == kind:
        return value
    size, real = len(kind.names), kind.fields["s0"][0].kind == "f"
    items = [float(v) if real else int(v) for v in value]
    if len(items) > size:
        raise TypeError(f"{len(items)} values do not fit a {size}-vector")
    return np.array(tuple(items + [0] * (size - len(items))), dtype=kind)  # 0-d, as pyopencl.cltypes makes
