"""A command's outputs: all published together at its end, after its report, or none (coordinates.md §4)."""

import errno
import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from clwave.cli import Terminated, main
from clwave.errors import OutputExistsError
from clwave.io.files import published_together, write_atomic

ROOT = Path(__file__).resolve().parents[1]
COMPRESS = ["compress", "phantom:hydrogen:16", "--levels", "1"]
RENDER = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "8"]


def names(folder) -> list:
    return sorted(p.name for p in Path(folder).iterdir())


@pytest.mark.parametrize("quantise", [[], ["--quantise", "1e-3"]])
def test_a_signal_while_the_error_is_measured_leaves_no_clw(tmp_path, capsys, monkeypatch, quantise):
    """compress measures its error before it publishes the file: SIGTERM then (exit 143) leaves nothing, and a retry
    is not refused for a file the failed run left (a quantised model reads the file back under a temporary name)."""
    import clwave.frames

    def stopped(values):
        raise Terminated()

    monkeypatch.setattr(clwave.frames, "root_mean_square", stopped)
    assert main(COMPRESS + ["-o", str(tmp_path / "x.clw")] + quantise) == 143
    assert names(tmp_path) == [] and capsys.readouterr().err == "clwave: terminated\n"


def test_an_error_that_cannot_be_measured_for_memory_is_said_and_the_file_kept(tmp_path, capsys, monkeypatch):
    """The error is a report on the file, not the file: no memory to rebuild the volume beside its model is said in
    the report, the file published, exit 0 (it was: exit 2, advice to render fewer pixels, and the file kept)."""
    import clwave.frames

    def short(values):
        raise MemoryError()

    monkeypatch.setattr(clwave.frames, "root_mean_square", short)
    assert main(COMPRESS + ["-o", str(tmp_path / "x.clw")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == ("error                 not measured: not enough memory to rebuild the volume beside it (the "
                       "file is complete)") and names(tmp_path) == ["x.clw"]


def test_compress_over_its_own_input_reports_the_inputs_size(tmp_path, capsys):
    """``compress same.clw -o same.clw --force``: the input line gives the size of the file read, not of the one
    written over it."""
    path = tmp_path / "same.clw"
    assert main(["compress", "phantom:hydrogen:32", "--levels", "2", "--keep", "0.5", "-o", str(path)]) == 0
    before = path.stat().st_size
    capsys.readouterr()
    assert main(["compress", str(path), "--keep", "0.1", "-o", str(path), "--force"]) == 0
    from clwave.cli.options import file_size
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith(f", {file_size(before)} on disk") and path.stat().st_size < before, out


def test_a_full_disk_at_the_last_output_publishes_none(tmp_path, capsys, monkeypatch):
    """``render -o a.png --raw a.npy --stats a.json`` with the disk full when the figures are written: one line,
    exit 2, and neither the image nor the raw values published (they were, one at a time)."""
    import clwave.io.result

    def full_at_json(path, writer, overwrite=False):
        def failing(fh):
            raise OSError(errno.ENOSPC, "No space left on device")
        return write_atomic(path, failing if str(path).endswith(".json") else writer, overwrite)

    monkeypatch.setattr(clwave.io.result, "write_atomic", full_at_json)
    code = main(RENDER + ["-o", str(tmp_path / "a.png"), "--raw", str(tmp_path / "a.npy"),
                          "--stats", str(tmp_path / "a.json")])
    err = capsys.readouterr().err
    assert code == 2 and err == (f"clwave: error: cannot write {tmp_path / 'a.json'}: No space left on device; check "
                                 f"the folder's permissions and free space\n")
    assert names(tmp_path) == []


def test_a_stdout_that_takes_nothing_is_one_line_and_publishes_nothing(tmp_path, capsys, monkeypatch):
    """``render ... >/dev/full``: one line naming stdout, exit 2, the image not published (it was: an internal error,
    exit 1, after the PNG was written)."""
    with open("/dev/full", "w") as full:
        monkeypatch.setattr(sys, "stdout", full)
        code = main(RENDER + ["-o", str(tmp_path / "a.png")])
    err = capsys.readouterr().err
    assert code == 2 and err == ("clwave: error: cannot write to standard output: No space left on device; nothing "
                                 "was published (point stdout at a file or a pipe that takes it)\n"), err
    assert names(tmp_path) == []


def test_a_buffered_stdout_that_takes_nothing_exits_2_not_120(tmp_path):
    """Without PYTHONUNBUFFERED the report waits in stdout's buffer; its flush fails before the file is published,
    and the interpreter's own last flush says nothing more (Python exits 120 when that fails)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "clwave", *COMPRESS, "-o", str(tmp_path / "x.clw")], stdout=full,
                              stderr=subprocess.PIPE, text=True, cwd=ROOT, env=dict(env, PYTHONPATH=str(ROOT)),
                              timeout=120)
    assert proc.returncode == 2 and proc.stderr.splitlines() == [
        "clwave: error: cannot write to standard output: No space left on device; nothing was published (point "
        "stdout at a file or a pipe that takes it)"], proc.stderr
    assert names(tmp_path) == []


def test_a_frames_folder_filled_by_another_run_meanwhile_is_refused(tmp_path, capsys, monkeypatch):
    """Two ``progressive -o pf`` into one empty folder: the one that finishes second is told, as for a single file,
    and the folder holds the first one's frames alone, never a mix (it was: both exit 0, the frames overwritten)."""
    module = importlib.import_module("clwave.progressive")  # clwave.progressive is the function too
    folder = tmp_path / "pf"
    folder.mkdir()
    original = module.progressive

    def raced(*args, **kwargs):  # the other run publishes its frames while this one renders
        frames = list(original(*args, **kwargs))
        (folder / "frame_000.png").write_bytes(b"the other run's")
        return frames

    monkeypatch.setattr(module, "progressive", raced)
    code = main(["progressive", "phantom:hydrogen:16", "--levels", "1", "--size", "8", "--steps", "2",
                 "-o", str(folder)])
    err = capsys.readouterr().err
    assert code == 2 and err == f"clwave: error: {folder} appeared while it was being written (another writer?); " \
                                "pass --force to replace it\n", err
    assert names(folder) == ["frame_000.png"] and (folder / "frame_000.png").read_bytes() == b"the other run's"
    assert names(tmp_path) == ["pf"]  # no temporary folder left beside it


def test_published_together_publishes_all_or_none(tmp_path):
    """The API under the commands: nothing named until publish(); a name taken meanwhile fails the publication and
    removes what it had published; leaving the ``with`` without publishing leaves nothing."""
    with published_together() as outputs:
        write_atomic(tmp_path / "a.npy", lambda fh: fh.write(b"a"))
        write_atomic(tmp_path / "b.json", lambda fh: fh.write(b"b"))
        assert names(tmp_path) == [] and Path(outputs.readable(tmp_path / "a.npy")).read_bytes() == b"a"
    assert names(tmp_path) == []
    with published_together() as outputs:
        write_atomic(tmp_path / "a.npy", lambda fh: fh.write(b"a"))
        write_atomic(tmp_path / "b.json", lambda fh: fh.write(b"b"))
        (tmp_path / "b.json").write_bytes(b"another writer's")
        with pytest.raises(OutputExistsError, match="appeared while it was being written"):
            outputs.publish()
    assert names(tmp_path) == ["b.json"] and (tmp_path / "b.json").read_bytes() == b"another writer's"
    (tmp_path / "b.json").unlink()
    with published_together() as outputs:
        write_atomic(tmp_path / "a.npy", lambda fh: fh.write(b"a"))
        frames = outputs.folder(tmp_path / "f")
        write_atomic(frames / "frame_000.png", lambda fh: fh.write(b"f"))
        outputs.publish()
    assert names(tmp_path) == ["a.npy", "f"] and names(tmp_path / "f") == ["frame_000.png"]
    assert (tmp_path / "f").stat().st_mode & 0o777 == 0o777 & ~_umask()


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def test_a_chunked_compression_is_the_same_file_at_every_run(tmp_path, capsys):
    """Dask's threads finish the blocks in any order; the file is written from them in their order, so that it is
    the same byte for byte at every run (it was not: the runs and chunks came in as the blocks finished)."""
    import numpy as np

    volume = tmp_path / "v.npy"
    np.save(volume, np.random.default_rng(1).random((128, 128, 128), np.float32))  # 64 blocks: 8 came in order
    runs = []
    for i in range(2):
        out = tmp_path / f"{i}.clw"
        assert main(["compress", str(volume), "--chunks", "32", "-o", str(out)]) == 0
        runs.append(out.read_bytes())
    assert runs[0] == runs[1]
