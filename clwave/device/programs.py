"""Build OpenCL programs from ``cl/`` and hand out each kernel object once per thread.

Sources live in ``cl/`` by pipeline stage (``common/``, ``splat/``, ``raytrace/``,
``device/``) and are named, and ``#include``-d, by their path below ``cl/``: they are
compiled with ``-I <cl dir>`` and ``-DCLW_SRC_HASH=<sha1 of every cl/ file>``, so an
edited header invalidates both pyopencl's and PoCL's binary caches.  ``prg.kernel_name``
creates a new Kernel on every access (pyopencl#830); :class:`KernelSet`
fetches each one once for each thread that launches it (a launch sets its arguments, then enqueues).
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import time
import warnings
from functools import lru_cache
from pathlib import Path

from . import constants
from .kernels import BUFFER, Kernel
from .context import INSTALL_HINT, ComputeContext, python_sigint
from ..errors import KernelBuildError
from ..io.progress import status

BUILD_QUIET_SECONDS = 1.0  # a build shows its status after this long, longer than a cached one (known-gaps.md §17)


def cl_dir() -> Path:
    """The kernel source folder: inside the installed package, else the checkout's ``cl/``."""
    package = Path(__file__).resolve().parents[1]
    for candidate in (package / "cl", package.parent / "cl"):
        if candidate.is_dir():
            return candidate
    raise KernelBuildError(f"kernel sources not found next to {package}; reinstall clwave")


@lru_cache(maxsize=None)
def source_hash(folder: Path) -> str:
    digest = hashlib.sha1()
    for path in sorted(folder.rglob("*")):
        if path.suffix in (".cl", ".h"):
            digest.update(path.relative_to(folder).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


class KernelSet:
    """A built program and its kernels: ``ks["name"]`` or ``ks.name``, each thread's own, fetched once per thread.  A
    launch sets a kernel's arguments one call at a time and then enqueues it: two threads launching one kernel object
    could each enqueue the other's arguments (two ray tracers set up at once gave wrong bricks until thread22), and a
    lock around each launch held the viewer's build thread up behind its render thread (docs/coordinates.md §4)."""

    def __init__(self, program, build_seconds: float, options: list):
        self.program = program
        self.build_seconds = build_seconds
        self.options = options
        self._mine = threading.local()

    def __getitem__(self, name):
        kernels = getattr(self._mine, "kernels", None)
        if kernels is None:
            kernels = self._mine.kernels = {k.function_name: k for k in self.program.all_kernels()}
        return kernels[name]

    def __getattr__(self, name):
        if name.startswith("_"):  # not a kernel's: self._mine before __init__ has set it (copy, pickle)
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None


def build(cc: ComputeContext, files, defines=None, options=()) -> KernelSet:
    """Build (or reuse) the program made of ``files`` (paths below ``cl/``) with ``-D`` ``defines``
    and the shared constants (:func:`clwave.device.constants.defines`), and compiler ``options``."""
    files, options = tuple(files), tuple(options)
    defines = tuple(sorted({**constants.defines(), **(defines or {})}.items()))
    # one build per program: a thread that asks for one another thread is building waits for it
    return cc.programs.get((files, defines, options), lambda: _build(cc, files, defines, options))


def _build(cc: ComputeContext, files, defines, options) -> KernelSet:
    import pyopencl as cl

    folder = cl_dir()
    source = "\n".join(f'#include "{name}"' for name in files) + "\n"
    # -w: PoCL prints ABI notes about float16 vectors straight to stderr otherwise
    flags = ["-I", str(folder), f"-DCLW_SRC_HASH={source_hash(folder)}", "-w", *options]
    flags += [f"-D{k}" if v is None else f"-D{k}={v}" for k, v in defines]
    start = time.perf_counter()
    python_sigint()
    try:
        with warnings.catch_warnings():  # non-empty logs of successful builds (PoCL ABI notes) are kept, not shown
            warnings.simplefilter("ignore", cl.CompilerWarning)
            with status("building OpenCL kernels (once per machine)…", BUILD_QUIET_SECONDS):
                program = cl.Program(cc.ctx, source).build(options=flags)
    except cl.Error as exc:
        log = str(exc)
        first = next((ln.strip() for ln in log.splitlines() if "error" in ln.lower()), log.strip()[:200])
        raise KernelBuildError(
            f"OpenCL build of {', '.join(files)} failed on {cc.info.name} ({first}); "
            f"if the driver is broken, {INSTALL_HINT}", log=log) from None
    seconds = time.perf_counter() - start
    if os.environ.get("CLW_BUILD_LOG"):  # one JSON line a build, for counting builds (docs/benchmarks.md §22)
        with open(os.environ["CLW_BUILD_LOG"], "a") as log:
            log.write(json.dumps(dict(files=files, defines=defines, options=options, seconds=round(seconds, 3),
                                      test=os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0])) + "\n")
    return KernelSet(program, seconds, flags)


SELFTEST = Kernel("selftest_axpy", ("alpha", "float32"), ("a", BUFFER), ("b", BUFFER), ("out", BUFFER))


def selftest(cc: ComputeContext, n: int = 1024) -> float:
    """Build and run ``selftest_axpy``; returns the build time, raises on a wrong answer."""
    import numpy as np
    import pyopencl.array as cla

    ks = build(cc, ["device/selftest.cl"])
    rng = np.random.default_rng(0)
    a, b = rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)
    d_a, d_b = cla.to_device(cc.queue, a), cla.to_device(cc.queue, b)
    d_out = cla.empty_like(d_a)
    SELFTEST(ks, cc.queue, (n,), None, alpha=2.5, a=d_a, b=d_b, out=d_out)
    got = d_out.get()
    if not np.allclose(got, 2.5 * a + b, rtol=1e-6, atol=1e-6):
        raise KernelBuildError(f"the self-test kernel gave wrong results on {cc.info.name}; "
                               f"{INSTALL_HINT}")
    return ks.build_seconds
