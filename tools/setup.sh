#!/usr/bin/env bash
# clwave set-up: idempotent, works on a bare Debian machine as root.
#
#   bash tools/setup.sh            install only
#   bash tools/setup.sh --demo     install, then compress and render the built-in hydrogen phantom
#   bash tools/setup.sh --test     install (and Debian's chromium with its driver, for the viewer's browser
#                                  tests, and clang, for the kernels' portability tests), then run the tests
#   bash tools/setup.sh --peers    also install the peers and figures extras (VTK, matplotlib, nilearn)
#                                  and the Mesa EGL libraries VTK renders offscreen with, for
#                                  tools/compare_peers.py and tools/figures.py; and DiffDRR on Debian's
#                                  python3-torch in .peers-venv, for tools/drr_peer.py
#
# Steps: Python 3 with venv (apt-get if missing) -> virtual environment .venv (CLWAVE_VENV
# overrides) -> `pip install .[test]` -> an OpenCL self-test kernel; when no working OpenCL
# platform exists, Debian's pocl-opencl-icd is installed (after apt-get update) and the
# self-test runs again.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${CLWAVE_VENV:-.venv}"
mode="${1:-}"
case "$mode" in ""|--demo|--test|--peers) ;; *) echo "usage: bash tools/setup.sh [--demo|--test|--peers]" >&2; exit 2 ;; esac

say() { printf '\n==> %s\n' "$*"; }

apt_updated=""
apt_install() {
    if ! command -v apt-get >/dev/null || [ "$(id -u)" != 0 ]; then
        echo "clwave setup: please install these system packages (as root): $*" >&2
        return 1
    fi
    if [ -z "$apt_updated" ]; then apt-get update -qq; apt_updated=1; fi
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@"
}

if ! command -v python3 >/dev/null || ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
    say "installing Python 3 with venv"
    apt_install python3 python3-venv python3-pip ca-certificates
fi

if [ ! -x "$VENV/bin/python" ]; then
    say "creating the virtual environment $VENV"
    python3 -m venv "$VENV"
fi
say "installing clwave and its test dependencies into $VENV"
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check ".[test]"

if ! "$VENV/bin/clwave" info --check >/dev/null 2>&1; then
    say "no working OpenCL platform: installing Debian's pocl-opencl-icd"
    apt_install pocl-opencl-icd ocl-icd-libopencl1
fi
say "OpenCL devices"
"$VENV/bin/clwave" info --check

case "$mode" in
    --demo)
        mkdir -p out
        say "demo: the hydrogen phantom, classified, cubic wavelets, 3 levels, 5 % kept"
        "$VENV/bin/clwave" compress phantom:hydrogen:128 --tf hydrogen --keep 0.05 -o out/hydrogen.clw --force
        say "demo: X-ray image by wavelet splatting -> out/hydrogen_splat.png"
        "$VENV/bin/clwave" render phantom:hydrogen:128 --keep 0.05 --size 512 -o out/hydrogen_splat.png --force
        say "demo: shaded emission-absorption image by ray tracing -> out/hydrogen_raytrace.png"
        "$VENV/bin/clwave" render phantom:hydrogen:96 --tf hydrogen --keep 0.05 --method raytrace --size 256 \
            --tolerance 1e-2 -o out/hydrogen_raytrace.png --force
        say "demo: progressive refinement -> out/hydrogen_progressive.gif (figures in .json)"
        "$VENV/bin/clwave" progressive phantom:hydrogen:128 --keep 0.05 --steps 8 --size 256 \
            -o out/hydrogen_progressive.gif --stats out/hydrogen_progressive.json --force
        ;;
    --test)
        if ! command -v chromedriver >/dev/null || ! { command -v chromium >/dev/null || command -v chromium-browser >/dev/null; }; then
            say "installing Debian's chromium and chromium-driver (the viewer's tests drive the page in it)"
            apt_install chromium chromium-driver || echo "clwave setup: without chromium the viewer's browser tests are skipped" >&2
        fi
        if ! compgen -c clang | grep -qE '^clang(-[0-9]+)?$'; then
            say "installing Debian's clang (the kernels' portability tests compile them for GPUs with it)"
            apt_install clang || echo "clwave setup: without clang the kernels' portability tests are skipped" >&2
        fi
        say "running the tests"
        # two workers, each given whole files (their module fixtures built once): one process's main thread does
        # three quarters of its CPU (kernel builds, NumPy oracles), so a second core is otherwise idle much of the time
        "$VENV/bin/python" -m pytest -q -n 2 --dist loadfile
        ;;
    --peers)
        say "installing the peers and figures extras (VTK, matplotlib, nilearn) into $VENV"
        "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check ".[test,peers,figures]"
        vtk_egl() {  # VTK's offscreen window on Mesa's EGL (llvmpipe); no display needed
            VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow "$VENV/bin/python" -c '
import vtkmodules.vtkRenderingOpenGL2
from vtkmodules.vtkRenderingCore import vtkRenderWindow
w = vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(8, 8); w.Render()
assert type(w).__name__ == "vtkEGLRenderWindow" and w.SupportsOpenGL()' >/dev/null 2>&1
        }
        if ! vtk_egl; then
            say "VTK cannot render offscreen: installing Mesa's EGL (libegl1 libegl-mesa0 libgl1-mesa-dri)"
            apt_install libegl1 libegl-mesa0 libgl1-mesa-dri
            vtk_egl || { echo "clwave setup: VTK still cannot open an EGL window" >&2; exit 1; }
        fi
        say "VTK renders offscreen through EGL; run python tools/compare_peers.py and python tools/figures.py"
        # DiffDRR (tools/drr_peer.py, docs/peers.md §5) in a venv of its own on Debian's CPU PyTorch: PyPI's torch
        # pulls the CUDA stack (several GB); diffdrr without its plotting and learning extras
        PEERS="${CLWAVE_PEERS_VENV:-.peers-venv}"
        if [ ! -x "$PEERS/bin/python" ] || ! "$PEERS/bin/python" -c "import diffdrr.drr" >/dev/null 2>&1; then
            say "installing DiffDRR on Debian's python3-torch into $PEERS"
            if apt_install python3-torch python3-venv; then
                /usr/bin/python3 -m venv --system-site-packages "$PEERS"
                "$PEERS/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps "diffdrr==0.6.1"
                "$PEERS/bin/python" -m pip install --quiet --disable-pip-version-check fastcore einops nibabel \
                    "torchio==0.19.*" "numpy<2" "pandas<2.3" "scipy<1.14"
            else
                echo "clwave setup: without python3-torch, tools/drr_peer.py skips DiffDRR" >&2
            fi
        fi
        say "run python tools/drr_peer.py --peer-python $PEERS/bin/python (DiffDRR; skipped where absent)"
        ;;
esac
