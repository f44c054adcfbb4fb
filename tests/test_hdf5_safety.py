"""Hostile HDF5 .clw files (docs/chunked.md §4): whatever points outside the file, aliases, loops, runs a
filter the writer does not use or holds unbounded data is refused with one line before any data is read."""

import json
import os
import shutil
import subprocess
import sys
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

import clwave
from clwave.errors import FileFormatError

ROOT = Path(__file__).resolve().parents[1]


def hostile(model_file, tmp_path, change) -> Path:
    """A copy of ``model_file`` written anew member by member, with ``change(h5 file, tmp_path)`` applied."""
    out = tmp_path / "hostile.clw"
    with h5py.File(model_file, "r") as src, h5py.File(out, "w") as h5:
        for name, value in src.attrs.items():
            h5.attrs[name] = value
        for name in src:
            src.copy(src[name], h5, name)
        change(h5, tmp_path)
    return out


def refused(path, needle):
    with pytest.raises(FileFormatError, match=needle) as err:
        clwave.WaveletVolume.open(path)
    assert "\n" not in str(err.value)
    return str(err.value)


def replace_values(h5, **how):
    """``g0/values`` replaced by a dataset of the same shape and type made with ``how``."""
    old = h5["g0/values"]
    shape, dtype, data = old.shape, old.dtype, old[...]
    del h5["g0/values"]
    h5.create_dataset("g0/values", shape=shape, dtype=dtype, **how)
    return data


def external_storage(h5, tmp_path):
    secret = tmp_path / "secret"
    secret.write_bytes(b"password" * 4096)
    replace_values(h5, external=[(str(secret), 0, h5py.h5f.UNLIMITED)])


def external_link(h5, tmp_path):
    other = tmp_path / "other.clw"
    shutil.copy(h5.filename, other)  # a valid model elsewhere, which the link would read
    del h5["g0/values"]
    h5["g0/values"] = h5py.ExternalLink(str(other), "/g0/values")


def soft_link_loop(h5, tmp_path):
    del h5["g0/values"]
    h5["g0/values"] = h5py.SoftLink("/g0/again")
    h5["g0/again"] = h5py.SoftLink("/g0/values")


def virtual(h5, tmp_path):
    source = tmp_path / "source.h5"
    data = h5["g0/values"][...]
    with h5py.File(source, "w") as f:
        f["v"] = data
    layout = h5py.VirtualLayout(shape=data.shape, dtype=data.dtype)
    layout[...] = h5py.VirtualSource(str(source), "v", shape=data.shape)
    del h5["g0/values"]
    h5.create_virtual_dataset("g0/values", layout)


def not_an_object(h5, tmp_path):
    h5.attrs["header"] = "[]"
    h5.attrs["header_crc32"] = zlib.crc32(b"[]")


def hard_link_alias(h5, tmp_path):
    h5["g0/also"] = h5["g0/values"]


def hard_link_loop(h5, tmp_path):
    h5["g0/up"] = h5["/"]


def lzf(h5, tmp_path):
    h5["g0/values"][...] = replace_values(h5, chunks=True, compression="lzf")


def tiny_chunks(h5, tmp_path):
    h5["g0/values"][...] = replace_values(h5, chunks=(1, 1))


def committed_type(h5, tmp_path):
    h5["type"] = np.dtype("f4")


def references(h5, tmp_path):
    h5.create_dataset("refs", data=[h5["g0"].ref], dtype=h5py.ref_dtype)


def variable_length(h5, tmp_path):
    h5.create_dataset("g0/vlen", shape=(2,), dtype=h5py.vlen_dtype(np.float32))


def compound(h5, tmp_path):
    h5.create_dataset("g0/pairs", shape=(2,), dtype=[("a", "f4"), ("b", "i4")])


def string_data(h5, tmp_path):
    h5["g0/text"] = ["one", "two"]


def empty_space(h5, tmp_path):
    h5["g0/nothing"] = h5py.Empty("f4")


def many_attributes(h5, tmp_path):
    for i in range(40):
        h5["g0"].attrs[f"a{i}"] = i


def big_fixed_attribute(h5, tmp_path):
    h5["g0/values"].attrs["blob"] = np.zeros(1 << 20, np.float32)


def reference_attribute(h5, tmp_path):
    h5["g0"].attrs.create("ref", h5["g0"].ref, dtype=h5py.ref_dtype)


def deep(h5, tmp_path):
    h5.create_group("a/b/c/d/e/f")


@pytest.mark.parametrize("change, needle", [
    (external_storage, "g0/values keeps its data in another file"),
    (external_link, "g0/values is an external link"),
    (soft_link_loop, "g0/(again|values) is a soft link"),
    (virtual, "g0/values is a virtual dataset"),
    (not_an_object, "the header is a JSON list, not an object"),
    (hard_link_alias, "linked from more than one place"),
    (hard_link_loop, "linked from more than one place"),
    (lzf, "filtered by 'lzf'"),
    (tiny_chunks, "g0/values has chunks of \\(1, 1\\)"),
    (committed_type, "type is a named datatype"),
    (references, "refs holds reference elements"),
    (variable_length, "vlen holds variable-length elements"),
    (compound, "pairs holds compound elements"),
    (string_data, "text holds string elements"),
    (empty_space, "nothing is not an array"),
    (many_attributes, "g0 has 40 attributes"),
    (big_fixed_attribute, "attribute 'blob'"),
    (reference_attribute, "attribute 'ref' of reference type"),
    (deep, "nests groups deeper"),
])
def test_hostile_members_are_refused(model_file, tmp_path, change, needle):
    refused(hostile(model_file, tmp_path, change), needle)


def test_the_copy_the_hostile_files_start_from_is_read(model_file, tmp_path):
    """The baseline: a member-by-member copy of a written file is read as the original."""
    back = clwave.WaveletVolume.open(hostile(model_file, tmp_path, lambda h5, _: None))
    whole = clwave.WaveletVolume.open(model_file)
    assert np.array_equal(back.groups[0].values, whole.groups[0].values)


def test_external_storage_is_refused_before_the_file_it_names_is_opened(model_file, tmp_path):
    def elsewhere(h5, tmp_path):  # a file that cannot be read: any attempt to read it would fail differently
        replace_values(h5, external=[(str(tmp_path / "does-not-exist"), 0, h5py.h5f.UNLIMITED)])
    refused(hostile(model_file, tmp_path, elsewhere), "keeps its data in another file")


def test_a_huge_header_attribute_is_refused_without_reading_it(model_file, tmp_path):
    """A 64 MB variable-length header lives in a heap its attribute does not measure: the bytes the file holds
    beyond its datasets' data tell, before it is read (reading it would take ~5 times its size)."""
    def huge(h5, _):
        h5.attrs["header"] = " " * (64 << 20)
    path = hostile(model_file, tmp_path, huge)
    script = f"""
import resource, clwave
from clwave.errors import FileFormatError
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    clwave.WaveletVolume.open({str(path)!r})
except FileFormatError as exc:
    print(exc)
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024)
"""
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    message, grown_mib = out.stdout.splitlines()
    assert "bytes beyond its datasets' data" in message and int(grown_mib) < 16, out.stdout + out.stderr


def test_a_header_at_the_limit_is_still_read(model_file, tmp_path):
    """The bound on what lies beyond the data leaves room for a header of MAX_HEADER characters."""
    from clwave.io.clw import MAX_HEADER

    def padded(h5, _):
        header = json.loads(h5.attrs["header"])
        text = json.dumps(header)
        text = text[:-1] + " " * (MAX_HEADER - len(text)) + "}"
        h5.attrs["header"], h5.attrs["header_crc32"] = text, zlib.crc32(text.encode())
    back = clwave.WaveletVolume.open(hostile(model_file, tmp_path, padded))
    assert back.kept == clwave.WaveletVolume.open(model_file).kept


def test_a_filter_the_writer_does_not_use_is_refused_before_hdf5_looks_for_it(model_file, tmp_path, monkeypatch):
    """bzip2 (id 307), which hdf5plugin registers but a .clw writer never uses: refused by its id, before HDF5
    would run it (or, unregistered, search HDF5_PLUGIN_PATH for a library of that id)."""
    import hdf5plugin

    def bzip2(h5, _):
        h5["g0/values"][...] = replace_values(h5, chunks=True, **hdf5plugin.BZip2())
    monkeypatch.setenv("HDF5_PLUGIN_PATH", str(tmp_path / "plugins"))
    refused(hostile(model_file, tmp_path, bzip2), "id 307")


@pytest.mark.parametrize("how", ["external storage", "virtual", "external link", "soft link"])
def test_an_hdf5_volume_input_is_read_from_its_own_file_only(tmp_path, how):
    """A volume input (.h5) whose dataset's data is elsewhere: refused, never read (the other file is a valid
    volume, which a silent read would return)."""
    other, path = tmp_path / "other.h5", tmp_path / "input.h5"
    data = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    with h5py.File(other, "w") as f:
        f["v"] = data
        offset = f["v"].id.get_offset()
    with h5py.File(path, "w") as h5:
        if how == "external storage":
            h5.create_dataset("v", shape=data.shape, dtype=data.dtype, external=[(str(other), offset, data.nbytes)])
        elif how == "virtual":
            layout = h5py.VirtualLayout(shape=data.shape, dtype=data.dtype)
            layout[...] = h5py.VirtualSource(str(other), "v", shape=data.shape)
            h5.create_virtual_dataset("v", layout)
        elif how == "external link":
            h5["v"] = h5py.ExternalLink(str(other), "/v")
        else:
            h5["w"] = np.zeros(3)
            h5["v"] = h5py.SoftLink("/elsewhere")
    with pytest.raises(FileFormatError) as err:
        clwave.load(f"{path}:/v")
    assert "\n" not in str(err.value)
    assert ("another file" in str(err.value) or "virtual" in str(err.value)) if "link" not in how \
        else "holds no array /v" in str(err.value)
