"""OpenCL device choice and the one context holder used everywhere.

``device=`` (API) and ``--device`` (CLI) accept ``auto``, ``cpu``, ``gpu``,
``P:D`` platform/device indices, ``P`` (first device of platform P; an int too) or a
case-insensitive substring of "platform device" names; an empty string is refused.  When the request is
``None`` or ``auto``, ``CLWAVE_DEVICE`` and then ``PYOPENCL_CTX`` are honoured;
nothing ever prompts.  ``auto`` prefers a GPU, then any accelerator, then a CPU
(PoCL first).
"""

from __future__ import annotations

import os
import signal
import threading
from dataclasses import dataclass

import numpy as np

from ..errors import DeviceNotFoundError, InputError
from ..threads import MadeOnce
from .kernels import Locked

INSTALL_HINT = ("install an OpenCL driver, e.g. Debian's `apt-get install pocl-opencl-icd`, "
                "or run tools/setup.sh")


@dataclass(frozen=True)
class DeviceInfo:
    """One OpenCL device with the figures `clwave info` prints."""

    platform_index: int
    device_index: int
    platform: str
    name: str
    kind: str  # "GPU", "CPU" or "ACCELERATOR"
    global_mem: int
    max_alloc: int
    local_mem: int
    compute_units: int
    version: str

    @property
    def id(self) -> str:
        return f"{self.platform_index}:{self.device_index}"

    @property
    def is_pocl(self) -> bool:
        return "portable computing language" in self.platform.lower() or "pocl" in self.platform.lower()

    def describe(self) -> dict:
        return dict(id=self.id, platform=self.platform, device=self.name, type=self.kind,
                    global_mem_bytes=self.global_mem, max_alloc_bytes=self.max_alloc,
                    local_mem_bytes=self.local_mem, compute_units=self.compute_units,
                    version=self.version, is_pocl=self.is_pocl)


def _cl():
    try:
        import pyopencl
    except ImportError as exc:  # the wheel bundles a loader, so this is a broken install
        raise DeviceNotFoundError(f"pyopencl cannot be imported ({exc}); {INSTALL_HINT}") from None
    return pyopencl


def _platforms():
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        platforms = []
    if not platforms:
        raise _not_found("no OpenCL platform found")
    return platforms


def _not_found(what) -> DeviceNotFoundError:
    """No platform or no device: none installed, or, under a memory limit (``ulimit -v``), a driver that could not
    load for memory, which the ICD loader does not tell apart (PoCL needs 500 to 700 MB of address space; known-gaps
    §15)."""
    import resource

    from .memory import available_bytes, format_size

    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit == resource.RLIM_INFINITY:
        return DeviceNotFoundError(f"{what}; {INSTALL_HINT}")
    return DeviceNotFoundError(f"{what}, with this process's memory limited to {format_size(limit)} (ulimit -v; "
                               f"{format_size(available_bytes())} of it left): an OpenCL driver that cannot load for "
                               f"memory is not found; raise the limit, or {INSTALL_HINT}")


def list_devices() -> list[DeviceInfo]:
    """Every device of every platform, in platform/device index order."""
    cl = _cl()
    out = []
    for p_idx, platform in enumerate(_platforms()):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for d_idx, dev in enumerate(devices):
            kind = ("GPU" if dev.type & cl.device_type.GPU else
                    "ACCELERATOR" if dev.type & cl.device_type.ACCELERATOR else "CPU")
            out.append(DeviceInfo(p_idx, d_idx, platform.name.strip(), dev.name.strip(), kind,
                                  int(dev.global_mem_size), int(dev.max_mem_alloc_size),
                                  int(dev.local_mem_size), int(dev.max_compute_units),
                                  dev.version.strip()))
    if not out:
        raise _not_found("OpenCL platforms exist but report no device")
    return out


def _auto_rank(info: DeviceInfo):
    kind_rank = {"GPU": 0, "ACCELERATOR": 1, "CPU": 2}[info.kind]
    return (kind_rank, not info.is_pocl, -info.compute_units, -info.global_mem,
            info.platform_index, info.device_index)


def requested_device(request=None) -> str:
    """The effective request string after the environment variables."""
    return _request(request)[0]


def _request(request):
    """(the effective request, the environment variable it came from or None)."""
    if isinstance(request, (int, np.integer)) and not isinstance(request, bool):
        request = str(int(request))  # a platform index, as "P"
    elif request is not None and not (isinstance(request, str) and request.strip()):
        raise InputError(f"device={request!r} names no device: give 'auto' (or None), 'cpu', 'gpu', 'P:D' platform "
                         f"and device indices, a platform index P, or part of a device's name",
                         cli=f"--device {request!r} names no device: give auto, cpu, gpu, P:D, P or part of a name")
    if request is None or request.strip().lower() == "auto":
        for var in ("CLWAVE_DEVICE", "PYOPENCL_CTX"):
            value = os.environ.get(var, "").strip()
            if value:
                return value, var
        return "auto", None
    return str(request).strip(), None


def select_device(request=None, devices=None) -> DeviceInfo:
    """Resolve a device request (see module docstring) to one :class:`DeviceInfo`."""
    devices = list_devices() if devices is None else devices
    req, var = _request(request)
    key = req.lower()
    if key == "auto":
        return min(devices, key=_auto_rank)
    if key in ("cpu", "gpu"):
        matches = [d for d in devices if d.kind == key.upper()]
    elif _is_index(key):
        parts = [int(p) if p else 0 for p in key.split(":")]
        p_idx, d_idx = parts[0], (parts[1] if len(parts) > 1 else 0)
        matches = [d for d in devices if (d.platform_index, d.device_index) == (p_idx, d_idx)]
    else:  # a substring of the platform or device name; "pocl" names PoCL's platform
        key = _ALIASES.get(key, key)
        matches = [d for d in devices if key in f"{d.platform} {d.name}".lower()]
    if not matches:
        known = "; ".join(f"{d.id} {d.platform} / {d.name} ({d.kind})" for d in devices)
        given = "" if var is None else f" (the environment variable {var}: change or unset it)"
        raise DeviceNotFoundError(f"no OpenCL device matches {req!r}{given}; available: {known}")
    return min(matches, key=_auto_rank)


_ALIASES = {"pocl": "portable computing language"}


def _is_index(key: str) -> bool:
    parts = key.split(":")
    return 1 <= len(parts) <= 2 and all(p.isdigit() or p == "" for p in parts) and parts[0] != ""


class ComputeContext:
    """An OpenCL context and in-order queue on one device, plus its built programs.

    Obtain one with :meth:`get`; equal requests share one holder, so kernels are
    built once per process.  Pass a ``ComputeContext`` anywhere ``device=`` is
    accepted.
    """

    _shared: dict = {}

    def __init__(self, info: DeviceInfo):
        cl = _cl()
        platform = _platforms()[info.platform_index]
        self.info = info
        self.device = platform.get_devices()[info.device_index]
        self.ctx = cl.Context([self.device])
        self.queue = cl.CommandQueue(self.ctx, properties=cl.command_queue_properties.PROFILING_ENABLE)
        self.programs = MadeOnce()
        # held by a render on this device (threads.one_at_a_time): a renderer's buffers are shared by its views, and
        # pyopencl's own array kernels (a pass's sum) by every thread (two renderers in two threads crashed or gave
        # wrong images until api22; each thread's kernels of clwave's programs are its own since thread22)
        self.lock = threading.RLock()
        # held by each call of a generated kernel (generated) and pyopencl's take: their kernel objects are shared by
        # every thread, and a launch sets the arguments one call at a time, which another thread's launch could
        # overwrite before the enqueue (two ray tracers' set-ups gave wrong bricks until thread22); apart from
        # ``lock``, so that a set-up on another thread (the viewer's build thread) need not wait for a render's view
        self.launch_lock = threading.RLock()

    @classmethod
    def get(cls, device=None) -> "ComputeContext":
        if isinstance(device, ComputeContext):
            return device
        info = select_device(device)
        if info not in cls._shared:
            cls._shared[info] = cls(info)
            python_sigint()
        return cls._shared[info]

    def generated(self, name: str, make):
        """One of pyopencl's generated kernels (element-wise, reduction, scan), made by ``make()`` the first
        time ``name`` is asked for in this context and reused after: making one builds a program each time.  Each
        call holds :attr:`launch_lock` (its kernel object is every thread's)."""
        return self.programs.get(name, lambda: Locked(make(), self.launch_lock))

    def upload(self, host):
        """A read-only device buffer holding a copy of a (non-empty) host array, in one call
        (cheaper than ``pyopencl.array.to_device`` for the many small tables of a view)."""
        cl = _cl()
        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                         hostbuf=np.ascontiguousarray(host))

    def describe(self) -> dict:
        return self.info.describe()

    def __repr__(self):
        return f"ComputeContext({self.info.id} {self.info.platform} / {self.info.name})"


def python_sigint():
    """Put Python's own SIGINT handling back (what ``signal.getsignal`` says it is: Ctrl-C as KeyboardInterrupt, or
    ignored), at the C level.  PoCL's LLVM installs a handler of its own when a context is made, which deletes the
    files of a build under way before it passes the signal on: a Ctrl-C during a build could fail it (an internal error
    where every other Ctrl-C ends "interrupted"), and so could a SIGINT the process ignores.  A handler is the
    process's, for every thread, but Python sets one from its main thread only: a build on another thread relies on
    the call :meth:`ComputeContext.get` makes when it makes the context on the main thread (the command line's)."""
    handler = signal.getsignal(signal.SIGINT)
    if handler is not None and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, handler)
