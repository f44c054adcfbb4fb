"""What landed in the twentieth session attacked (attack25): MRC/CCP4 and MGH headers, the scale bar, label maps;
each defect found pinned here, its fix at its one home."""

import tracemalloc

import numpy as np
import pytest

import clwave
from test_mgh import assert_refused_in_one_line
from test_mrc import _valid, _with


def test_an_mrc_extended_header_longer_than_the_file_is_refused_before_it_is_read(tmp_path, capsys):
    """nsymbt 2^31 - 1 in a 1.3 kB file: mrcfile read (allocated) its 2 GiB before finding the file short."""
    path = tmp_path / "bad.mrc"
    path.write_bytes(_with(_valid(tmp_path), 92, np.int32(2 ** 31 - 1).tobytes()))
    tracemalloc.start()
    try:
        with pytest.raises(clwave.errors.FileFormatError):
            clwave.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 24, f"{peak:,} bytes allocated"
    assert_refused_in_one_line(capsys, path, r"declares an extended header of 2,147,483,647 bytes but the file holds "
                                             r"240 bytes after its 1,024-byte header")
