"""Ctrl-C while an OpenCL program is built: PoCL's LLVM takes SIGINT over when a context is made (device/context.py,
``python_sigint``, called by ``ComputeContext.get`` and before each build); a build runs under Python's own handling,
so that it ends as every other Ctrl-C does."""

import os
import signal
import subprocess
import sys

from test_hardening import ROOT, interrupted, sigint_default

#: the C-level SIGINT handler seen by each real build (the script's ``pyopencl.Program.build`` wrapped), against
#: Python's own at the start: the address of ``sigaction``'s handler, its first field on Linux
SEEN_BY_BUILDS = """
import ctypes, signal, sys
import pyopencl as cl

libc = ctypes.CDLL(None, use_errno=True)

def handler():
    action = (ctypes.c_void_p * 32)()
    assert libc.sigaction(signal.SIGINT, None, action) == 0
    return action[0]

python_handler = handler()
_build, seen = cl.Program.build, []

def build(self, *args, **kwargs):
    seen.append(handler() == python_handler)
    return _build(self, *args, **kwargs)

cl.Program.build = build
from clwave.device.context import ComputeContext, select_device
from clwave.device.programs import build, selftest

cc = ComputeContext(select_device(None))  # made directly, not by ``get``: LLVM's handler stays
llvm = handler() != python_handler
selftest(cc)
build(cc, ["device/selftest.cl"], defines=dict(CLW_TEST_SIGNALS=None))
ComputeContext.get(None)
print(llvm, seen, handler() == python_handler)
"""


def test_a_build_runs_under_pythons_own_sigint_handling():
    """Once a context is made its SIGINT handler is LLVM's; each build runs under Python's (a Ctrl-C there is a
    KeyboardInterrupt), and under SIG_IGN where the process ignores SIGINT (a background job): never LLVM's, which
    deletes the build's files."""
    for ignored in (False, True):
        proc = subprocess.run([sys.executable, "-c", SEEN_BY_BUILDS], cwd=ROOT, capture_output=True, text=True,
                              timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                              preexec_fn=(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if ignored
                              else sigint_default)
        assert proc.returncode == 0, proc.stderr[-2000:]
        # the context's handler is not Python's (else this test tests nothing), no build ran under it, and a
        # context made by ``ComputeContext.get`` leaves Python's in place
        assert proc.stdout.strip() == "True [True, True] True", (ignored, proc.stdout)


def test_the_command_line_puts_pythons_handling_back_once_it_has_a_context(tmp_path):
    """`clwave render` makes its context while checking its options (the image size against the device): by the
    decomposition, before any build, SIGINT is Python's again (a build on a viewer's thread could not put it back)."""
    script = SEEN_BY_BUILDS.split("cl.Program.build = build")[0] + f"""
from clwave import cli
from clwave.model.wavelet import WaveletVolume

def decompose(*args, **kwargs):
    print(handler() == python_handler, flush=True)
    raise SystemExit(0)

WaveletVolume.from_volume = decompose
cli.main(["render", "phantom:marschner-lobb:16", "--size", "16", "-o", {str(tmp_path / 'o.png')!r}])
"""
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0 and proc.stdout.strip() == "True", (proc.stdout, proc.stderr[-2000:])


def test_ctrl_c_during_a_kernel_build_is_interrupted(tmp_path):
    """SIGINT sent while a kernel is built (empty caches, so that it compiles): "clwave: interrupted", code 130,
    nothing written, as every other Ctrl-C."""
    script = f"""
import os, sys
os.environ["POCL_CACHE_DIR"] = {str(tmp_path / 'pocl')!r}
os.environ["PYOPENCL_NO_CACHE"] = "1"
from clwave import cli
from clwave.device import programs
_build = programs.build
def announced(cc, files, *args, **kwargs):
    if "device/selftest.cl" not in files:
        print("launched", flush=True)
    return _build(cc, files, *args, **kwargs)
programs.build = announced
sys.exit(cli.main(["render", "phantom:marschner-lobb:16", "--levels", "1", "--size", "16",
                   "-o", {str(tmp_path / 'out' / 'o.png')!r}]))
"""
    (tmp_path / "out").mkdir()
    _, code, _, err = interrupted(script, b"clwave: interrupted")
    assert code == 130 and err.decode().strip().splitlines()[-1] == "clwave: interrupted", err.decode()[-2000:]
    assert "internal error" not in err.decode() and not list((tmp_path / "out").iterdir())
