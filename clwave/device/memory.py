"""Memory figures, the device's and the host's.

How much device memory a renderer may hold: the device's own limits, or less where the user caps it
(``device_memory=`` in the API, ``--device-memory`` on the command line); docs/splatting.md §6.
:func:`parse_size` reads a cap (bytes, or a string with a binary unit); :func:`device_budget` gives the
budget a renderer plans its buffers within, :func:`check_buffer` refuses one buffer beyond it naming the true fix (a
larger cap, or where the device's own limit is met whatever the cap, the caller's); :func:`format_size` writes sizes
for messages.

How much host memory there is to spend (:func:`available_bytes`): work that cannot fit is refused before it
starts (:func:`check_fits`).  An image, both (:func:`check_image`).
"""

from __future__ import annotations

import ctypes
import os
import re
from math import ceil, isqrt
from dataclasses import dataclass

from ..errors import ClwaveError, DeviceMemoryError, InputError

#: what :func:`parse_size` accepts, as its errors say it
SIZE_FORMS = ("a whole number of bytes (e.g. 536870912) or a number with a binary unit K, M, G or T "
              "(KiB, MiB, GiB, TiB), e.g. '512MiB', '2GiB', '1.5G', '800M'")

_SIZE = re.compile(r"(\d+(?:\.\d+)?)\s*([KMGT](?:iB)?)?", re.IGNORECASE)
_UNITS = dict(K=2**10, M=2**20, G=2**30, T=2**40)


def parse_size(value, name: str = "device_memory") -> int:
    """Bytes from ``value``: a positive int, or a string of a number and a binary unit ("2GiB",
    "512MiB", "1.5G", "800M"; K, M, G, T are powers of 1024, case-insensitive; decimal units such as
    "GB" are refused as ambiguous).  Anything else, or less than one byte, is an :class:`InputError`
    naming ``name`` (an API argument; the command line's ``--name`` in its words)."""
    flag = "--" + name.replace("_", "-")
    if isinstance(value, str):
        match = _SIZE.fullmatch(value.strip())
        if match is None or (match.group(2) is None and "." in match.group(1)):  # no fractions of a byte
            raise InputError(f"{name}={value!r} is not a size: give {SIZE_FORMS}",
                             cli=f"{flag} {value} is not a size: give {SIZE_FORMS}")
        number, unit = match.groups()
        value = int(float(number) * _UNITS[unit[0].upper()]) if unit else int(number)
    elif isinstance(value, bool) or not hasattr(value, "__index__"):
        raise InputError(f"{name}={value!r} is not a size: give {SIZE_FORMS}")
    if int(value) < 1:
        raise InputError(f"{name}={value!r} must be at least one byte: give {SIZE_FORMS}",
                         cli=f"{flag} {value} must be at least one byte")
    return int(value)


def parse_cap(value, name: str = "device_memory") -> int | None:
    """:func:`parse_size` of a cap that may be absent (None: no cap)."""
    return None if value is None else parse_size(value, name)


@dataclass(frozen=True)
class DeviceBudget:
    """Device memory a renderer may hold at once (``total``) and in one buffer (``max_alloc``), in bytes;
    ``cap`` is the user's cap (None: the device's memory is the budget)."""

    total: int
    max_alloc: int
    cap: int | None = None


def device_budget(cc, device_memory=None) -> DeviceBudget:
    """The budget on ``cc`` (a :class:`~clwave.device.context.ComputeContext`): its global memory and
    allocation limit, each no more than ``device_memory`` (bytes or a size string, :func:`parse_size`), nor, on a CPU
    device, whose memory is the host's, than the host has available now (:func:`available_bytes`: PoCL's global
    memory is the machine's, whatever other processes hold)."""
    info = cc.info
    cap = parse_cap(device_memory)
    total = info.global_mem if cap is None else min(cap, info.global_mem)
    if info.kind == "CPU":
        total = min(total, available_bytes())
    return DeviceBudget(total, min(info.max_alloc, total), cap)


#: bytes per pixel of the device buffer a renderer holds for a whole image: the splatting framebuffer (RGBA float32,
#: per layer) and the ray tracer's image with its statistics; each renderer checks its own with :func:`check_buffer`
#: as it begins an image, and the viewer both before it reads its input (cli/view.py)
FRAMEBUFFER_PIXEL_BYTES = 16
TRACED_PIXEL_BYTES = 32
#: bytes per pixel the host holds of a finished image: its float32 RGBA read back (RenderResult.image) and an 8-bit
#: RGBA picture made from it
HOST_PIXEL_BYTES = 20


def buffer_limit(cc, share: float = 1.0) -> int:
    """The most one device buffer may take on ``cc``'s device, whatever the cap: its own limit per buffer, and
    ``share`` of its memory."""
    return min(cc.info.max_alloc, int(cc.info.global_mem * share))


def check_buffer(cc, nbytes: int, what: str, fix: str, budget: DeviceBudget | None = None, share: float = 1.0):
    """Refuse (a :class:`DeviceMemoryError`) one device buffer of ``nbytes`` over what one may take: the device's
    own limit per buffer, or within ``budget``, its most per buffer and ``share`` of its total.  The message names
    the true fix: where the user's cap holds it back, the least cap that lets it be (``device_memory=``,
    ``--device-memory``); where the device does, ``fix`` (``what`` needs...; ``fix``: "render a smaller image")."""
    own = buffer_limit(cc, share)
    room = own if budget is None else min(budget.max_alloc, int(budget.total * share))
    if nbytes <= room:
        return
    need = f"{what} needs {format_size(nbytes)} in one device buffer"
    if nbytes <= own:  # only the user's cap, budget.cap, holds it back
        cap, least = format_size(budget.cap), format_size(ceil(nbytes / share))
        raise DeviceMemoryError(f"{need}, more than device_memory={cap} allows; give device_memory= at least {least}, "
                                f"or {fix}", cli=f"{need}, more than --device-memory {cap.replace(' ', '')} allows; "
                                                 f"give --device-memory {least.replace(' ', '')} or more, or {fix}")
    raise DeviceMemoryError(f"{need}, but {cc.info.name} allows {format_size(own)} whatever the device memory given; "
                            f"{fix}")


def check_image(cc, size, device_bytes: int, fix: str, budget: DeviceBudget | None = None, what: str = "a {}x{} image",
                least: int = 0):
    """Refuse an image of ``size`` (H, W) before its buffers are made, in one line naming it (``what``, "HxW" in its
    braces), the bytes it needs and ``fix`` (its ``{n}``: the largest square image that would fit): the least device
    memory its renderer needs for it in all, ``least`` (the splatter's framebuffers, tile lists, count tables and a
    least chunk of coefficients), beyond ``budget``'s total (:func:`too_little`); its renderer's device buffer of
    ``device_bytes`` (:func:`check_buffer`); then its memory on the host (:func:`check_fits`: a
    :class:`HostMemoryError`): the image read back, :data:`HOST_PIXEL_BYTES` a pixel, and where ``cc``'s device is
    the CPU, whose memory is the host's, the device's share too (the larger of ``least`` and ``device_bytes``).
    ``cc`` None: the host's share alone (a camera's size, before any device)."""
    pixels = size[0] * size[1]
    image = what.format(*size)
    on_host = HOST_PIXEL_BYTES * pixels
    if cc is not None:
        if budget is not None and least > budget.total:
            too_little(cc, budget, f"a {size[0]}x{size[1]} view needs at least {format_size(least)} of device memory "
                                   f"before its footprints (framebuffers, tile lists and its first coefficients)",
                       fix.format(n=isqrt(int(budget.total * pixels / least))))
        per_pixel = device_bytes / pixels
        check_buffer(cc, device_bytes, image, fix.format(n=isqrt(int(buffer_limit(cc) / per_pixel))), budget)
        on_host += max(device_bytes, least) if cc.info.kind == "CPU" else 0
    check_fits(on_host, image, fix.format(n=isqrt(int(available_bytes() * pixels / on_host))))


def too_little(cc, budget: DeviceBudget, need: str, fix: str):
    """Raise the :class:`DeviceMemoryError` of work that needs more device memory in all than ``budget`` holds, in
    ``need``'s words ("a 512x512 view needs at least 53 MiB of device memory (...)"): the cap too small where the
    user's holds it back, else the device's memory and ``fix``."""
    if budget.cap is not None and budget.cap < cc.info.global_mem:
        cap = format_size(budget.cap)
        raise DeviceMemoryError(f"device_memory={cap} is too small: {need}; give more or {fix}",
                                cli=f"--device-memory {cap} is too small: {need}; give more or {fix}")
    raise DeviceMemoryError(f"{cc.info.name} has {format_size(budget.total)}, and {need}; {fix}")


def format_size(nbytes: int) -> str:
    """``nbytes`` in the largest binary unit that keeps it at least 1, rounded up so that a minimum stays
    one ("37 MiB", "1.5 GiB", "812 KiB", "100 bytes")."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= size:
            digits = 1 if nbytes < 10 * size else 0
            scale = 10 ** digits
            value = -(-nbytes * scale // size) / scale  # rounded up
            return f"{value:.{digits}f} {unit}".replace(".0 ", " ")
    return f"{nbytes} bytes"


class HostMemoryError(ClwaveError, MemoryError):
    """Work refused before it starts: it would not fit in the host's memory."""


def out_of_threads(exc) -> bool:
    """Whether ``exc`` is Python's refusal to start a thread: the process has no memory left for the thread's stack
    (``ulimit -v``) or may start no more threads (``ulimit -u``), which no input causes."""
    return isinstance(exc, RuntimeError) and str(exc).startswith("can't start new thread")


def available_bytes() -> int:
    """Memory this process could get now: the system's (Linux: MemAvailable, else the physical memory), no more than
    its address-space limit leaves (``ulimit -v``: the limit less what is mapped already) nor its cgroup's
    (``memory.max`` less ``memory.current``), which refuse an allocation the system's memory would take."""
    try:
        with open("/proc/meminfo") as fh:
            free = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable:"))
    except (OSError, StopIteration):  # pragma: no cover - not Linux
        free = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return min([free] + _limited_room())


def _limited_room() -> list:
    """Bytes this process may still map under its address-space limit and its cgroup v2's memory limit, where
    they are set (Linux)."""
    room = []
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit != resource.RLIM_INFINITY:
            with open("/proc/self/status") as fh:
                mapped = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
            room.append(max(limit - mapped, 0))
    except (ImportError, OSError, StopIteration):  # pragma: no cover - not Linux
        pass
    try:
        with open("/sys/fs/cgroup/memory.max") as fh:
            limit = fh.read().strip()
        if limit != "max":
            with open("/sys/fs/cgroup/memory.current") as fh:
                room.append(max(int(limit) - int(fh.read()), 0))
    except (OSError, ValueError):  # no cgroup v2 at its usual place
        pass
    return room


def return_freed() -> bool:
    """Give the memory this process has freed back to the system, where the C library keeps it (glibc's
    ``malloc_trim``; elsewhere nothing, False).  glibc keeps freed chunks for reuse in its heaps (other threads'
    allocations in heaps of their own); the large buffers that come next (a pass's bricks, on PoCL the device's memory
    is the host's) are mapped anew and cannot reuse them (docs/raytracing.md §6)."""
    trim = getattr(_libc(), "malloc_trim", None)
    return bool(trim(0)) if trim is not None else False


def _libc():
    try:
        return ctypes.CDLL(None)  # the symbols this process has loaded (its C library among them)
    except (OSError, TypeError):  # pragma: no cover - Windows
        return None


def check_fits(nbytes: int, what: str, hint: str):
    """A :class:`HostMemoryError` naming ``what`` and the numbers when ``nbytes`` exceed what is available."""
    free = available_bytes()
    if nbytes > free:
        raise HostMemoryError(f"{what} needs about {format_size(nbytes)}, and this machine has "
                              f"{format_size(free)} available; {hint}")
