"""A command's outputs: all published together at its end, before its report, or none (coordinates.md §4)."""

import errno
import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from clwave.cli import Terminated, main
from clwave.cli.options import file_size
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


LOST = ("clwave: warning: cannot write to standard output: No space left on device; point stdout at a file or a pipe "
        "that takes it; the outputs are published, the report lost")


def test_a_stdout_that_takes_nothing_is_a_warning_after_the_outputs_are_published(tmp_path, capsys, monkeypatch):
    """``render ... >/dev/full``: the outputs published first, then the report, which stdout does not take: one
    warning line, exit 0 (it was: exit 2 and nothing published; before that an internal error, exit 1, after the
    PNG was written)."""
    with open("/dev/full", "w") as full:
        monkeypatch.setattr(sys, "stdout", full)
        code = main(RENDER + ["-o", str(tmp_path / "a.png")])
    err = capsys.readouterr().err
    assert code == 0 and err == LOST + "\n", err
    assert names(tmp_path) == ["a.png"]


def test_a_buffered_stdout_that_takes_nothing_exits_0_not_120(tmp_path):
    """Without PYTHONUNBUFFERED the report waits in stdout's buffer; its flush fails after the file is published,
    and the interpreter's own last flush says nothing more (Python exits 120 when that fails)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "clwave", *COMPRESS, "-o", str(tmp_path / "x.clw")], stdout=full,
                              stderr=subprocess.PIPE, text=True, cwd=ROOT, env=dict(env, PYTHONPATH=str(ROOT)),
                              timeout=120)
    assert proc.returncode == 0 and proc.stderr.splitlines() == [LOST], proc.stderr
    assert names(tmp_path) == ["x.clw"]


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


def test_a_failed_publication_with_force_puts_the_replaced_files_back(tmp_path, capsys):
    """``--force`` over a.png and b.npy, and a later output that cannot be published (a folder took its name after
    the checks): the old a.png and b.npy put back, no temporary left, nothing reported (it was: the new ones kept,
    mixed with the old, and a hidden ``.x.json.PID.FD.tmp`` left behind)."""
    (tmp_path / "a.png").write_bytes(b"old a")
    (tmp_path / "b.npy").write_bytes(b"old b")
    with pytest.raises(OSError), published_together() as outputs:
        for name in ("a.png", "b.npy", "x.json"):
            write_atomic(tmp_path / name, lambda fh, name=name: fh.write(b"new " + name.encode()), overwrite=True)
        (tmp_path / "x.json").mkdir()
        outputs.publish()
    assert names(tmp_path) == ["a.png", "b.npy", "x.json"]
    assert [(tmp_path / n).read_bytes() for n in ("a.png", "b.npy")] == [b"old a", b"old b"]
    with published_together() as outputs:  # published: the old files' links gone with them
        write_atomic(tmp_path / "a.png", lambda fh: fh.write(b"new a"), overwrite=True)
        outputs.publish()
    assert names(tmp_path) == ["a.png", "b.npy", "x.json"] and (tmp_path / "a.png").read_bytes() == b"new a"


def test_a_failed_publication_leaves_no_report(tmp_path, capsys, monkeypatch):
    """The outputs are published before the report, which so never names a file that is not there (it was printed
    first: a publication that failed after it left stdout naming outputs that did not exist)."""
    import clwave.io.files

    def refused(*args):
        raise OSError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(clwave.io.files, "_link_unnamed", refused)
    monkeypatch.setattr(clwave.io.files, "_publish", refused)
    code = main(RENDER + ["-o", str(tmp_path / "a.png")])
    out, err = capsys.readouterr()
    assert code == 2 and "splatted" not in out and str(tmp_path) not in out, out
    assert err.startswith(f"clwave: error: cannot write {tmp_path / 'a.png'}: Permission"), err
    assert names(tmp_path) == []


@pytest.mark.parametrize("quantise", [[], ["--quantise", "1e-3"]])
def test_compress_names_no_temporary_while_it_measures(tmp_path, capsys, monkeypatch, quantise):
    """compress takes its file's size from the open unnamed file: while it measures the error, the folder holds no
    name a SIGKILL (the OOM killer) would leave behind (it was: a hidden ``.x.PID.FD.clw`` at every run); a
    quantised model, read back through h5py and its content mask by name, is the one exception (known-gaps.md)."""
    import clwave.frames

    seen, measure = [], clwave.frames.root_mean_square

    def looking(values):
        seen.append(names(tmp_path))
        return measure(values)

    monkeypatch.setattr(clwave.frames, "root_mean_square", looking)
    assert main(COMPRESS + ["-o", str(tmp_path / "x.clw")] + quantise) == 0
    assert len(seen) == 1 and len(seen[0]) == (1 if quantise else 0) and names(tmp_path) == ["x.clw"]
    size = (tmp_path / "x.clw").stat().st_size  # the size reported is the published file's
    assert f"x.clw: {file_size(size)}, " in capsys.readouterr().out


def test_a_frames_folder_through_a_link_is_filled_in_place(tmp_path):
    """``-o LINK``, a symbolic link to an empty folder: the frames moved into that folder, which keeps its mode and
    setgid bit, the link kept (it was: "cannot write LINK: Not a directory", after rendering)."""
    folder, link = tmp_path / "frames", tmp_path / "link"
    folder.mkdir()
    folder.chmod(0o2750)
    link.symlink_to("frames")
    with published_together() as outputs:
        tmp = outputs.folder(link, replaces=r"frame_\d+\.png")
        write_atomic(tmp / "frame_000.png", lambda fh: fh.write(b"f"))
        outputs.publish()
    assert link.is_symlink() and names(folder) == ["frame_000.png"] and names(tmp_path) == ["frames", "link"]
    assert folder.stat().st_mode & 0o7777 == 0o2750


def test_a_folder_filled_meanwhile_is_refused_without_force(tmp_path):
    """An empty folder there at the check, filled by another writer before the publication: refused, its file kept,
    nothing of this run's moved in (coordinates.md §4)."""
    folder = tmp_path / "f"
    folder.mkdir()
    with published_together() as outputs:
        tmp = outputs.folder(folder)
        write_atomic(tmp / "frame_000.png", lambda fh: fh.write(b"mine"))
        (folder / "frame_001.png").write_bytes(b"theirs")
        with pytest.raises(OutputExistsError, match="appeared while it was being written"):
            outputs.publish()
    assert names(folder) == ["frame_001.png"] and names(tmp_path) == ["f"]
