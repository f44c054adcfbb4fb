"""Running out of memory or threads is named as such, with a fix for the command that ran out (trial22)."""

import resource

import pytest

from clwave.cli import main


def test_a_thread_that_cannot_start_is_not_called_a_corrupt_file(model_file, capsys, monkeypatch):
    """``can't start new thread`` (a memory limit leaves no room for a thread's stack) while a .clw is read: the
    process's limits, not "cannot read x.clw as a .clw file ... truncated or corrupt"."""
    import h5py

    def no_thread(*args, **kwargs):
        raise RuntimeError("can't start new thread")

    monkeypatch.setattr(h5py, "File", no_thread)
    assert main(["info", str(model_file)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clwave: error: not enough memory or threads for this work (can't start new thread; a "
                          "memory limit, ulimit -v, leaves no room for a thread's stack)") and err.count("\n") == 1


def test_compress_out_of_memory_names_compressions_fixes(tmp_path, capsys, monkeypatch):
    from clwave.model.wavelet import WaveletVolume

    def short(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(WaveletVolume, "from_volume", short)
    assert main(["compress", "phantom:hydrogen:16", "--levels", "1", "-o", str(tmp_path / "x.clw")]) == 2
    assert capsys.readouterr().err == ("clwave: error: not enough memory for this work (an allocation failed); keep "
                                       "fewer coefficients (--keep), read the volume chunk by chunk (--chunks auto) "
                                       "or crop it\n")


@pytest.mark.parametrize("found, what", [([], "no OpenCL platform found"), (None, "OpenCL platforms exist but report "
                                                                                  "no device")])
def test_no_opencl_under_a_memory_limit_names_the_limit(monkeypatch, found, what):
    """Under ``ulimit -v 500000`` PoCL cannot load and the ICD loader reports no platform (600000: no device); the
    message names the limit before the advice to install a driver."""
    import pyopencl

    from clwave.device import context
    from clwave.errors import DeviceNotFoundError

    class Platform:
        name = "a platform"

        def get_devices(self):
            return []

    monkeypatch.setattr(pyopencl, "get_platforms", lambda: [Platform()] if found is None else found)
    monkeypatch.setattr(resource, "getrlimit", lambda kind: (500000 * 1024, resource.RLIM_INFINITY))
    with pytest.raises(DeviceNotFoundError) as err:
        context.list_devices()
    assert str(err.value).startswith(f"{what}, with this process's memory limited to 489 MiB (ulimit -v; ") and \
        "an OpenCL driver that cannot load for memory is not found; raise the limit, or install" in str(err.value)
    monkeypatch.setattr(resource, "getrlimit", lambda kind: (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    with pytest.raises(DeviceNotFoundError, match=f"^{what}; install an OpenCL driver"):
        context.list_devices()


def test_footprint_textures_beyond_the_hosts_memory_name_memory_first(tmp_path, capsys, monkeypatch):
    """A 2 mm isotropic volume under a memory limit: not "the voxel spacing is very uneven"."""
    from clwave.device import memory

    monkeypatch.setattr(memory, "available_bytes", lambda: 1 << 16)
    assert main(["render", "phantom:hydrogen:16", "--levels", "1", "--spacing", "2", "--size", "32",
                 "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clwave: error: making the footprint textures of this view (") and \
        "and this machine has 64 KiB available; free memory (or raise this process's limit), give a lower omega_s " \
        "(--omega-s), or render with the ray tracer (--method raytrace)" in err and "uneven" not in err, err
