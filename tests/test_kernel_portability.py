"""Every kernel variant the renderers build compiles as OpenCL C 1.2 for NVIDIA's and AMD's GPUs.

No GPU has run clwave yet (docs/known-gaps.md §11), so the first GPU driver to see a kernel would be the first to
find what PoCL accepts and a GPU compiler does not (OpenCL 2.0 and 3.0 features, PoCL's extensions, undeclared
builtins).  These tests record the programs that tiny renders build, through every field, order, mode and stage,
and compile each with clang's GPU back ends, ``nvptx64-nvidia-nvcl`` and ``amdgcn-amd-amdhsa``, as OpenCL C 1.2
(NVIDIA's OpenCL C version) to device assembly, warnings as failures (docs/benchmarks.md §9).  clang comes with
Debian's PoCL (``libpocl2`` depends on it); ``tools/setup.sh --test`` installs it where it is missing.
"""

from __future__ import annotations

import shutil
import subprocess

import pytest

import clwave
from clwave.device import constants, programs

CLANG = next(filter(None, map(shutil.which, ["clang"] + [f"clang-{v}" for v in range(30, 13, -1)])), None)
pytestmark = pytest.mark.skipif(CLANG is None, reason="no clang: tools/setup.sh --test installs it (Debian: clang)")

#: clang's GPU targets, with OpenCL C 1.2: NVIDIA's compiler accepts no more
TARGETS = {"nvidia": ("-target", "nvptx64-nvidia-nvcl"),
           "amd": ("-target", "amdgcn-amd-amdhsa", "-mcpu=gfx90a", "-nogpulib")}


def _renders(cc):
    """Tiny renders through every kernel file and the modes that change their code (fields, orders, channels,
    precision, X-ray and shaded, post-classification, level of detail, perspective, splat variants)."""
    from clwave.splat.stages import Stages

    cam, cone = clwave.Camera(30, 20, size=16), clwave.ConeBeam(dso=60, dsd=90, size=16, pixel=2.0)
    volume = clwave.phantom("hydrogen", 20)
    rgba = clwave.TransferFunction.preset("hydrogen").classify(volume)
    scalar = clwave.WaveletVolume.from_volume(volume, levels=2).threshold(keep=0.6)
    models = {wavelet if isinstance(wavelet, str) else "mixed":
              clwave.WaveletVolume.from_volume(rgba, wavelet=wavelet, levels=2).threshold(keep=0.6)
              for wavelet in ("cubic", ["cubic"] * 3 + ["linear"], "haar", "quintic")}
    for wv in models.values():
        tracer = clwave.RayTracer(wv, device=cc)
        for precision in ("single", "double"):
            tracer.render(cam, tolerance=1e-2, precision=precision)
            tracer.render(cam, tolerance=1e-2, precision=precision, absorption=False)
    clwave.RayTracer(models["cubic"], device=cc, field="wavelet").render(cam, tolerance=1e-2)
    lod = clwave.RayTracer(scalar, device=cc, lod=True)
    for detail in (0, 2):
        lod.render(cam, tolerance=1e-2, detail=detail, transfer_function=clwave.TransferFunction.preset("hydrogen"))
    clwave.RayTracer(scalar, device=cc, content_clamp=False).render(cone, tolerance=1e-2, absorption=False)
    for variant in ("cpu", "gpu"):  # the device picks one; both are built here (the mixed model: 3 and 1 channels)
        renderer = clwave.SplatRenderer(models["mixed"], device=cc)
        for channels in (3, 1):
            for perspective in (False, True):
                renderer.stages[(channels, perspective)] = Stages(renderer.cc, channels, variant=variant,
                                                                  perspective=perspective)
        renderer.render(cam)
        renderer.render(cone)
    clwave.splat(scalar, cone, device=cc, coarse=1e-2)


@pytest.fixture(scope="module")
def variants(cc):
    """{(files, defines, options)} of every program the renders build, and the tests' harness kernels."""
    from test_classify import pool_kernels
    from test_normal_turns import build as quadrature_harness

    recorded, original = set(), programs.build

    def record(cc, files, defines=None, options=()):
        merged = tuple(sorted({**constants.defines(), **(defines or {})}.items()))
        recorded.add((tuple(files), merged, tuple(options)))
        return original(cc, files, defines, options)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(programs, "build", record)
        _renders(cc)
        quadrature_harness("single")
        quadrature_harness("double", samples=16)
        pool_kernels(cc)
        programs.build(cc, ["device/selftest.cl"])
    return recorded


def test_the_renders_build_every_kernel_file(variants):
    folder = programs.cl_dir()
    every = {p.relative_to(folder).as_posix() for p in folder.rglob("*.cl")}
    built = {name for files, _, _ in variants for name in files}
    assert every - built == set(), "kernel files nothing here builds: add what builds them to the recording"


@pytest.mark.parametrize("target", TARGETS)
def test_every_kernel_variant_compiles_for_gpus(variants, target, tmp_path):
    folder, failures = programs.cl_dir(), []
    for i, (files, defines, options) in enumerate(sorted(variants, key=repr)):
        source = tmp_path / f"v{i}.cl"
        source.write_text("".join(f'#include "{name}"\n' for name in files))
        flags = [f"-D{k}" if v is None else f"-D{k}={v}" for k, v in defines] + list(options)
        run = subprocess.run([CLANG, "-x", "cl", "-cl-std=CL1.2", *TARGETS[target], "-Xclang",
                              "-finclude-default-header", "-I", str(folder), *flags, "-Werror",
                              "-Wno-constant-logical-operand", "-Wno-unused-command-line-argument",
                              "-O0", "-S", "-o", str(tmp_path / f"v{i}.s"), str(source)],
                             capture_output=True, text=True, timeout=120)
        if run.returncode != 0:
            failures.append(f"{' '.join(files)} {' '.join(flags)}:\n{run.stderr[-1500:]}")
    assert not failures, f"{len(failures)} of {len(variants)} variants fail on {target}:\n" + "\n".join(failures[:3])
    assert len(variants) > 20  # the renders above took every path: a handful would mean the recording broke
