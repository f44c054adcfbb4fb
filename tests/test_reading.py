"""``loaders.shared.reading``, the one home of what a read's failure says: library errors as one FileFormatError
line, running out of memory as the machine's (HostMemoryError), the readers' log lines quiet while reads are under
way, on any number of threads (chunks are read at once by Dask's threads)."""

import logging
import threading

import pytest

from clwave.device.memory import HostMemoryError
from clwave.errors import FileFormatError
from clwave.io.loaders.shared import reading


def test_a_failed_read_says_the_file_and_running_out_of_memory_the_machine():
    with pytest.raises(FileFormatError, match="cannot read v.zarr: ValueError: bad; the file may be truncated"):
        with reading("v.zarr"):
            raise ValueError("bad")
    with pytest.raises(HostMemoryError, match=r"reading v.zarr ran out of memory \(Unable to allocate 2 GiB\); "
                                              r"read it in smaller chunks"):
        with reading("v.zarr"):
            raise MemoryError("Unable to allocate 2 GiB")


def test_overlapping_reads_on_threads_leave_the_readers_log_as_it_was(caplog):
    """Two reads overlapping (A starts, B starts, A ends, B ends) on two threads: tifffile's records are dropped
    while either is under way and pass again after both (a level saved and restored per read left it at CRITICAL)."""
    log = logging.getLogger("tifffile")
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()

    def a():
        with reading("a.tif"):
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def b():
        a_in.wait(5)
        with reading("b.tif"):
            b_in.set()
            a_out.wait(5)
            log.warning("inside a read")

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    log.warning("after the reads")
    assert [r.getMessage() for r in caplog.records if r.name == "tifffile"] == ["after the reads"]
