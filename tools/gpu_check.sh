#!/usr/bin/env bash
# clwave on a GPU, in one run of about five minutes: the OpenCL devices, the kernel tests against the GPU
# (CLWAVE_DEVICE), and the bench's views (tools/bench.py raytrace and splat: hydrogen, cubic, 3 levels, 5 %
# kept, 512^2, tolerance 1e-2) of a 256^3 and a 512^3 phantom rendered there, timed, and compared with the
# same renders on PoCL; the timings and errors go to OUT/gpu_check.json (docs/benchmarks.md §9).
#
#   bash tools/gpu_check.sh [--device gpu] [--out DIR] [--sizes "256 512"] [--image 512] [--reference DIR]
#                           [--save-reference DIR] [--wheels DIR] [--tests "FILES"] [--no-tests]
#
# --device         the device to check (default gpu; cpu checks the script on PoCL)
# --reference DIR  PoCL images made earlier (--save-reference DIR with --device cpu, here); without it, a CPU
#                  OpenCL device of the same machine renders them, and where there is none errors are not told
# --wheels DIR     wheels to install (no network needed) where clwave's dependencies are missing, e.g. made here
#                  with: python3 -m pip download --only-binary=:all: --python-version 3.12 --platform
#                  manylinux_2_28_x86_64 --platform manylinux2014_x86_64 -d DIR pyopencl PyWavelets mako
#                  (the rest of clwave's imports, numpy, scipy, h5py, imageio, tifffile, tqdm, are on the
#                  GPU machines); else tools/setup.sh sets up .venv (which needs a package index)
# --sizes          phantom sizes (default "256 512"); --image: the views' size; --tests: the kernel test files
#                  (default below).  tests/test_gpu_check.py runs it small on PoCL, so that it stays ready.
# Exit status: 0 when every step ran and every image is within its bound of its reference, 1 otherwise.
set -uo pipefail
cd "$(dirname "$0")/.."
device=gpu out=out/gpu_check sizes="256 512" image=512 reference="" save_reference="" wheels="" run_tests=1
tests="tests/test_device.py tests/test_splat_kernels.py tests/test_footprint.py tests/test_raytrace.py tests/test_bricks.py"
while [ $# -gt 0 ]; do
    case "$1" in
        --device) device="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --sizes) sizes="$2"; shift 2 ;;
        --image) image="$2"; shift 2 ;;
        --reference) reference="$2"; shift 2 ;;
        --save-reference) save_reference="$2"; shift 2 ;;
        --wheels) wheels="$2"; shift 2 ;;
        --tests) tests="$2"; shift 2 ;;
        --no-tests) run_tests=0; shift ;;
        *) echo "usage: see the head of $0" >&2; exit 2 ;;
    esac
done
mkdir -p "$out"
status=0
say() { printf '\n==> %s\n' "$*"; }

# ---- Python with clwave's dependencies: this checkout's clwave, always (PYTHONPATH)
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
needs='import numpy, scipy, pyopencl, pywt, mako, h5py, imageio, tqdm'
PY=""
for candidate in "${CLWAVE_PYTHON:-}" .venv/bin/python python3; do
    if [ -n "$candidate" ] && "$candidate" -c "$needs" 2>/dev/null; then PY="$candidate"; break; fi
done
if [ -z "$PY" ] && [ -n "$wheels" ]; then
    say "installing the wheels of $wheels into /tmp/clwave-site"
    python3 -m pip install -q --no-index --no-deps --no-compile --disable-pip-version-check --upgrade \
        --target /tmp/clwave-site "$wheels"/*.whl && export PYTHONPATH="$PYTHONPATH:/tmp/clwave-site"
    python3 -c "$needs" && PY=python3
fi
if [ -z "$PY" ]; then
    say "setting up .venv with tools/setup.sh"
    bash tools/setup.sh >"$out/setup.log" 2>&1 && PY=.venv/bin/python || { tail -5 "$out/setup.log"; exit 1; }
fi

# ---- an NVIDIA driver's OpenCL library without its ICD file: name it to the ICD loader
if [ -z "${OCL_ICD_VENDORS:-}" ] && ! ls /etc/OpenCL/vendors/*.icd >/dev/null 2>&1; then
    lib=$(ldconfig -p 2>/dev/null | awk '/libnvidia-opencl\.so/ {print $NF; exit}')
    [ -z "$lib" ] && lib=$(find /usr/local/nvidia /usr/lib /usr/lib64 -name 'libnvidia-opencl.so*' 2>/dev/null | head -1)
    if [ -n "$lib" ]; then
        mkdir -p /tmp/clwave-icd && echo "$lib" >/tmp/clwave-icd/nvidia.icd && export OCL_ICD_VENDORS=/tmp/clwave-icd
    fi
fi

say "OpenCL devices"
"$PY" -m clwave info 2>&1 | tee "$out/devices.txt" || status=1
"$PY" -c "import clwave, sys; clwave.ComputeContext.get(sys.argv[1])" "$device" \
    || { echo "no OpenCL device matches --device $device" >&2; exit 1; }

if [ "$run_tests" = 1 ]; then
    say "kernel tests on $device (CLWAVE_DEVICE=$device)"
    # shellcheck disable=SC2086
    CLWAVE_DEVICE="$device" timeout 240 "$PY" -m pytest -q -p no:cacheprovider $tests 2>&1 | tee "$out/tests.txt" | tail -15
    [ "${PIPESTATUS[0]}" = 0 ] || status=1
fi

say "the bench's views on $device"
"$PY" - "$device" "$out" "$sizes" "$image" "$reference" "$save_reference" <<'EOF' || status=1
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, "tools")
import clwave  # noqa: E402
from bench_common import machine, views  # noqa: E402  (the bench's views)

device, out, sizes, IMAGE, reference, save = sys.argv[1], Path(sys.argv[2]), [int(s) for s in sys.argv[3].split()], \
    int(sys.argv[4]), sys.argv[5], sys.argv[6]
KEEP, TOLERANCE, VIEWS = 0.05, 1e-2, 2
# bounds on max |image - PoCL image| / max |PoCL image|: ray tracing within its tolerance (an absolute error
# per value, the images are in [0, 1]); splatting: float32 sums in another order
BOUNDS = dict(raytrace=2 * TOLERANCE, splat=1e-4)


def cpu_reference():
    if reference or device == "cpu":
        return None
    try:
        return clwave.ComputeContext.get("cpu")
    except clwave.ClwaveError:
        return None


def renders(wv, method, dev):
    """(set-up seconds, [render seconds], [images]) of the bench's views; a warm-up view first."""
    start = time.perf_counter()
    if method == "raytrace":
        r = clwave.RayTracer(wv, device=dev)
        draw = lambda cam: r.render(cam, tolerance=TOLERANCE)  # noqa: E731
    else:
        r = clwave.SplatRenderer(wv, device=dev)
        draw = lambda cam: clwave.splat(wv, cam, renderer=r)  # noqa: E731
    setup = time.perf_counter() - start
    draw(clwave.Camera(10.0, 5.0, size=IMAGE))
    seconds, images = [], []
    for az, el in views(VIEWS):
        start = time.perf_counter()
        images.append(draw(clwave.Camera(az, el, size=IMAGE)).image)
        seconds.append(time.perf_counter() - start)
    return setup, seconds, images


cpu = cpu_reference()
report = dict(machine=machine(), device=clwave.ComputeContext.get(device).describe(), reference=
              reference or (cpu.describe() if cpu else None), image=IMAGE, keep=KEEP, tolerance=TOLERANCE,
              views=views(VIEWS), bounds=BOUNDS, cases={})
failed = False
for n in sizes:
    start = time.perf_counter()
    vol = clwave.phantom("hydrogen", n)
    tf = clwave.TransferFunction.preset("hydrogen")
    models = dict(raytrace=clwave.WaveletVolume.from_volume(tf.classify(vol), "cubic", levels=3).threshold(keep=KEEP),
                  splat=clwave.WaveletVolume.from_volume(vol, "cubic", levels=3).threshold(keep=KEEP))
    print(f"{n}^3: models in {time.perf_counter() - start:.1f} s", flush=True)
    for method, wv in models.items():
        name = f"{method} {n}"
        setup, seconds, images = renders(wv, method, device)
        case = dict(setup_seconds=setup, render_seconds=seconds, coefficients=wv.kept)
        if save:
            Path(save).mkdir(parents=True, exist_ok=True)
            for i, image in enumerate(images):
                np.save(Path(save, f"{method}_{n}_{i}.npy"), image)
        refs = None
        if reference:
            paths = [Path(reference, f"{method}_{n}_{i}.npy") for i in range(VIEWS)]
            refs = [np.load(p) for p in paths] if all(p.exists() for p in paths) else None
        elif cpu is not None:
            _, case["reference_render_seconds"], refs = renders(wv, method, cpu)
        if refs is not None:
            errors = [float(np.abs(a.astype(np.float64) - b).max() / max(np.abs(b).max(), 1e-30))
                      for a, b in zip(images, refs)]
            case.update(relative_max_errors=errors, within_bound=max(errors) <= BOUNDS[method])
            failed |= not case["within_bound"]
        report["cases"][name] = case
        told = (f"error against PoCL {max(case['relative_max_errors']):.2e} (bound {BOUNDS[method]:g})"
                if "relative_max_errors" in case else "no PoCL reference")
        print(f"{name:>13}: set-up {setup:.2f} s, views {', '.join(f'{s:.3f}' for s in seconds)} s; {told}",
              flush=True)
(out / "gpu_check.json").write_text(json.dumps(report, indent=2, default=str))
print(f"timings and errors -> {out / 'gpu_check.json'}")
sys.exit(1 if failed else 0)
EOF
say "done: $( [ $status = 0 ] && echo passed || echo FAILED ) (exit $status); files in $out"
exit $status
