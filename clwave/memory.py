"""How much host memory there is to spend: work that cannot fit is refused before it starts."""

from __future__ import annotations

import os

from .errors import ClwaveError


class HostMemoryError(ClwaveError, MemoryError):
    """Work refused before it starts: it would not fit in the host's memory."""


def available_bytes() -> int:
    """Memory the system could give this process now (Linux: MemAvailable), else the physical memory."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # pragma: no cover - not Linux
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_fits(nbytes: int, what: str, hint: str):
    """A :class:`MemoryError` naming ``what`` and the numbers when ``nbytes`` exceed what is available."""
    free = available_bytes()
    if nbytes > free:
        raise HostMemoryError(f"{what} needs about {nbytes / 2**30:,.1f} GiB, and this machine has "
                              f"{free / 2**30:,.1f} GiB available; {hint}")
