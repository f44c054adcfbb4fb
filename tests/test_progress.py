"""Progress of long steps: whether it shows (a terminal, a Jupyter kernel, a pipe; forced on or off by a call, by
clwave.show_progress or by the command line's --progress/--no-progress), and that long steps count their work."""

import io
import sys
import types
from functools import partialmethod

import dask
import numpy as np
import pytest
import tqdm.std

import clwave
from clwave.cli import main, make_parser
from clwave.errors import InputError
from clwave.io.progress import progress, show_progress, showing
from clwave.model.volume import Volume
from clwave.schedulers import client_for, stream


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture
def every_update(monkeypatch):
    """Every update drawn (tqdm draws at most one a 0.1 s by default), so that the stream counts them."""
    monkeypatch.setattr(tqdm.std.tqdm, "__init__", partialmethod(tqdm.std.tqdm.__init__, mininterval=0, miniters=1))


def kernel(monkeypatch, has_kernel=True):
    """This process as a Jupyter kernel's (IPython's shell with a kernel), or a plain IPython shell's."""
    shell = types.SimpleNamespace(kernel=object()) if has_kernel else types.SimpleNamespace()
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))


def counts(text, desc):
    """The counts ``desc``'s bar drew, in order."""
    return [int(frame.split("|")[2].split("/")[0]) for frame in text.split("\r") if frame.startswith(desc + ":")]


def test_a_bar_shows_on_a_terminal_and_in_a_kernel_not_in_a_pipe(monkeypatch):
    monkeypatch.setattr(sys, "stderr", Terminal())
    assert showing()
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a pipe, a file, CI's log
    assert not showing()
    kernel(monkeypatch, has_kernel=False)  # IPython in a terminal: its stderr decides
    assert not showing()
    kernel(monkeypatch)  # Jupyter: stderr is the kernel's stream, no terminal
    assert showing()


def test_forced_on_and_off_by_the_call_or_the_setting(monkeypatch):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert showing(True) and not showing(False)
    with show_progress(True):
        assert showing() and not showing(False)  # a call's own progress_bar= first
        with show_progress(False):
            assert not showing()
            monkeypatch.setattr(sys, "stderr", Terminal())
            assert not showing() and showing(True)
        assert showing()
    assert showing()  # on the terminal again, by itself
    try:
        show_progress(False)  # a call sets it for the session
        assert not showing()
    finally:
        show_progress(None)
    assert showing()


def test_a_setting_other_than_true_false_or_none_is_one_line():
    with pytest.raises(InputError, match=r"^show_progress='no' must be True or False$"):
        show_progress("no")
    assert clwave.show_progress is show_progress


def test_a_kernel_without_ipywidgets_gets_the_text_bar_on_stderr(monkeypatch, every_update):
    """No widget to draw: tqdm's text bar (Jupyter draws its carriage returns in place), and no warning."""
    kernel(monkeypatch)
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    for _ in progress(range(3), desc="work"):
        pass
    assert counts(sys.stderr.getvalue(), "work") == [0, 1, 2, 3]


def test_the_transform_counts_each_channels_levels_and_axes(monkeypatch, every_update):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    rgba = Volume(np.random.default_rng(1).random((8, 8, 8, 4), np.float32))
    clwave.WaveletVolume.from_volume(rgba, "linear", levels=1, progress_bar=True)
    assert counts(sys.stderr.getvalue(), "linear transform")[-1] == 4 * 3
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    scalar = Volume(rgba.data[..., 0])
    clwave.WaveletVolume.from_volume(scalar, "linear", levels=2, progress_bar=True)  # a scalar's bar moves too
    assert counts(sys.stderr.getvalue(), "linear transform") == list(range(7))
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    clwave.WaveletVolume.from_volume(scalar, "linear", levels=0, progress_bar=True)
    assert counts(sys.stderr.getvalue(), "linear transform") == [0, 1]
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    clwave.WaveletVolume.from_volume(rgba, "linear", levels=1)  # a pipe: nothing
    assert sys.stderr.getvalue() == ""


def test_dask_blocks_are_counted_in_their_order(monkeypatch, every_update):
    """The bar of a chunked pass counts the block results handed on (docs/chunked.md §5)."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    tasks = [dask.delayed(int)(i) for i in range(5)]
    with client_for(None) as client:
        assert list(stream(client, tasks, desc="blocks", progress_bar=True)) == list(range(5))
    assert counts(sys.stderr.getvalue(), "blocks") == [0, 1, 2, 3, 4, 5]


def test_a_chunked_models_content_pass_counts_its_blocks(monkeypatch, every_update):
    """A task a block through schedulers.stream: the box and range of the volume in memory, 2 x 2 x 2 blocks counted."""
    import dask.array as da

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    data = np.zeros((16, 16, 16), np.float32)
    data[3:9, 5:6, 2:14] = np.linspace(-2, 7, 12, dtype=np.float32)
    volume = Volume(data, spacing=(1, 2, 0.5))
    model = clwave.ChunkedWaveletVolume.from_volume(Volume(da.from_array(data, chunks=8), spacing=(1, 2, 0.5)),
                                                    levels=1, progress_bar=True)
    assert counts(sys.stderr.getvalue(), "content") == list(range(9))
    assert model.value_range == (-2.0, 7.0) == volume.value_range()
    assert np.array_equal(model.content, np.array(volume.content_box()))


def test_the_ray_tracers_set_up_counts_its_brick_layers(monkeypatch, every_update):
    """The bricks and a scalar's pool (a chunk of slots a step), each layer of bricks along z a step."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 48), levels=2).threshold(keep=0.2)
    with show_progress(True):
        tracer = clwave.RayTracer(wv)
    layers = len(np.unique(tracer.bricks.bricks[:, 0]))
    assert layers > 1
    assert counts(sys.stderr.getvalue(), "ray tracer bricks") == list(range(layers + 1))
    assert counts(sys.stderr.getvalue(), "scalar pool")[-1] >= 1
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    clwave.RayTracer(wv)  # a pipe: nothing
    assert sys.stderr.getvalue() == ""


def test_a_render_in_passes_counts_them_and_one_pass_shows_no_bar(monkeypatch, every_update):
    from test_bricks import out_of_core_model

    wv, camera = out_of_core_model(), clwave.Camera(30, 20, size=16)
    parts = clwave.RayTracer(wv, device_memory="14MiB")
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with show_progress(True):
        several = parts.render(camera, tolerance=1e-2).meta["passes"]
    assert several > 1 and counts(sys.stderr.getvalue(), "ray-tracing passes") == list(range(several + 1))
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    parts.render(camera, tolerance=1e-2)  # a pipe: nothing
    whole = clwave.RayTracer(wv)
    with show_progress(True):
        assert whole.render(camera, tolerance=1e-2).meta["passes"] == 1
    assert "ray-tracing passes" not in sys.stderr.getvalue()


def test_opening_a_file_counts_its_reads(tmp_path, monkeypatch, every_update):
    """The reads cut at multiples of READ_ROWS rows, each a step; the same model as one read each."""
    from clwave.io import clw

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1).threshold(keep=0.3)
    wv.save(tmp_path / "h.clw")
    whole = clwave.WaveletVolume.open(tmp_path / "h.clw")
    monkeypatch.setattr(clw, "READ_ROWS", 500)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with show_progress(True):
        cut = clwave.WaveletVolume.open(tmp_path / "h.clw")
    rows = wv.groups[0].kept
    for dataset in ("positions", "values"):
        assert counts(sys.stderr.getvalue(), f"reading g0/{dataset}") == list(range(-(-rows // 500) + 1))
    assert np.array_equal(cut.groups[0].all_positions(), whole.groups[0].all_positions())
    assert np.array_equal(cut.groups[0].values, whole.groups[0].values)


def test_thresholding_counts_the_coefficients_it_weighs_a_band_at_a_time(monkeypatch, every_update):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=2)
    with show_progress(True):
        wv.threshold(keep=0.1)
    ends = [0] + [sl.stop for sl in wv.groups[0].band_slices()]  # every band holds coefficients here
    assert len(ends) == 1 + 7 * 2 + 1 and ends[-1] == wv.groups[0].kept
    assert counts(sys.stderr.getvalue(), "importance") == ends


def test_the_splat_renderers_set_up_counts_its_ranked_blocks(monkeypatch, every_update):
    from clwave.model import ranking

    monkeypatch.setattr(ranking, "RANK_ROWS", 1024)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)
    with show_progress(True):
        clwave.SplatRenderer(wv)
    assert counts(sys.stderr.getvalue(), "ranked table") == list(range(-(-wv.groups[0].kept // 1024) + 1))


def test_the_auto_windows_pass_over_a_chunked_volume_shows_dasks_bar(monkeypatch):
    """The pass runs on Dask's local threads (no distributed client): Dask's own ProgressBar, on stderr."""
    import dask.array as da

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    volume = Volume(da.from_array(clwave.phantom("hydrogen", 16).data, chunks=8))
    hydrogen = clwave.TransferFunction.preset("hydrogen")
    with show_progress(True):
        shown = hydrogen.resolved(volume, "auto")
    assert "100% Completed" in sys.stderr.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert hydrogen.resolved(volume, "auto").window == shown.window  # a pipe: the same window, no bar
    assert sys.stderr.getvalue() == ""


def test_a_turntable_counts_its_views(monkeypatch, every_update):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)
    with show_progress(True):
        turn = clwave.turntable(wv, 3, clwave.Camera(size=(8, 8)))
        one = clwave.turntable(wv, 1, clwave.Camera(size=(8, 8)))  # one view: no bar
    assert len(turn) == 3 and len(one) == 1
    assert counts(sys.stderr.getvalue(), "turntable views") == [0, 1, 2, 3]


@pytest.mark.parametrize("command", ["compress", "render", "progressive", "drr", "view"])
def test_every_input_command_takes_progress_and_no_progress(command, capsys):
    with pytest.raises(SystemExit):
        make_parser().parse_args([command, "--help"])
    assert "--progress, --no-progress" in capsys.readouterr().out
    rest = {"drr": ["--poses", "p.csv", "-o", "x.npy"], "view": []}.get(command, ["-o", "x.png"])
    for given, value in ((["--progress"], True), (["--no-progress"], False), ([], None)):
        args = make_parser().parse_args([command, "phantom:hydrogen:16", *rest, *given])
        assert args.progress is value


def test_the_command_line_shows_progress_as_told(tmp_path, monkeypatch, every_update):
    """--progress shows it in a log (a pipe), --no-progress hides it on a terminal; the setting is put back."""
    def compress(*given):
        stderr = Terminal() if "--no-progress" in given else io.StringIO()
        monkeypatch.setattr(sys, "stderr", stderr)
        code = main(["compress", "phantom:hydrogen:16", "--levels", "1", "--tf", "hydrogen", "--force",
                     "-o", str(tmp_path / "h.clw"), *given])
        assert code == 0, stderr.getvalue()
        return stderr.getvalue()

    assert counts(compress("--progress"), "cubic transform") == list(range(4 * 3 + 1))  # channels x axes
    assert "transform" not in compress("--no-progress")
    assert "transform" not in compress()  # a pipe
    monkeypatch.setattr(sys, "stderr", Terminal())
    assert showing()


def test_progressive_counts_its_frames_and_drr_its_radiographs(tmp_path, monkeypatch, every_update):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert main(["progressive", "phantom:hydrogen:16", "--levels", "1", "--steps", "3", "--size", "8", "--progress",
                 "-o", str(tmp_path / "p.gif")]) == 0, sys.stderr.getvalue()
    assert counts(sys.stderr.getvalue(), "progressive frames") == [0, 1, 2, 3]
    (tmp_path / "t.csv").write_text("azimuth,elevation,dso\n0,0,60\n90,10,70\n")
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert main(["drr", "phantom:shepp-logan:16", "--levels", "1", "--poses", str(tmp_path / "t.csv"), "--size", "8",
                 "--pixel", "2", "--dsd", "90", "--progress", "-o", str(tmp_path / "d.npy")]) == 0, \
        sys.stderr.getvalue()
    assert counts(sys.stderr.getvalue(), "radiographs") == [0, 1, 2]


def test_a_status_shows_once_its_block_has_lasted_and_goes_when_it_ends(monkeypatch):
    from clwave.io.progress import status

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with status("waiting", after=3600, enabled=True):  # a quick block: its timer never fires
        pass
    assert sys.stderr.getvalue() == ""
    with status("waiting", after=0, enabled=True) as timer:
        timer.join()  # the block outlasts ``after``
        assert "waiting" in sys.stderr.getvalue()
    assert sys.stderr.getvalue().endswith("\r")  # cleared, as a bar is
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with status("waiting", after=0) as timer:  # a pipe: no thread, nothing
        assert timer is None
    assert sys.stderr.getvalue() == ""


def test_a_kernel_build_that_lasts_says_so_unless_told_not_to(cc, monkeypatch):
    """A slow build (every build here, with no wait) shows one status line; a quiet setting starts no timer."""
    import threading

    import pyopencl as cl

    from clwave.device import programs

    built = cl.Program.build

    def build_outlasting_the_wait(self, *args, **kwargs):
        program = built(self, *args, **kwargs)
        for thread in threading.enumerate():
            if isinstance(thread, threading.Timer):
                thread.join()
        return program

    monkeypatch.setattr(programs, "BUILD_QUIET_SECONDS", 0)
    monkeypatch.setattr(cl.Program, "build", build_outlasting_the_wait)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with show_progress(True):
        programs.build(cc, ["device/selftest.cl"], {"CLW_PROGRESS_TEST": 1})
    assert "building OpenCL kernels (once per machine)" in sys.stderr.getvalue()
    monkeypatch.setattr(sys, "stderr", Terminal())
    monkeypatch.setattr(threading.Timer, "start", lambda timer: pytest.fail("a timer under show_progress(False)"))
    with show_progress(False):
        programs.build(cc, ["device/selftest.cl"], {"CLW_PROGRESS_TEST": 2})
    assert sys.stderr.getvalue() == ""
