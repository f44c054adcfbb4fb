"""Splatting within a device-memory budget (docs/splatting.md §6): coefficients streamed to the device in
chunks in importance order against the same coefficients all on the device, and the budget itself
(clwave.device.memory)."""

import numpy as np
import pytest

import clwave
from clwave.device.memory import DeviceBudget, device_budget, format_size, parse_size
from clwave.errors import DeviceMemoryError, InputError
from clwave.splat import renderer as renderer_module

#: a cap that leaves a 32^2 view of 16^3 (29203 cubic coefficients, 2 levels) room for about 12000 at a time
CAP = "1600KiB"
#: float32 sums of the same terms in other groups (test_splat.py's splitting tests), relative to the image maximum
REGROUPED = 1e-5


@pytest.fixture(scope="module")
def wv():
    data = np.random.default_rng(7).random((16, 16, 16)).astype(np.float32)
    return clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)


@pytest.mark.parametrize("value, size", [("2GiB", 2 * 2**30), ("512MiB", 512 * 2**20), ("1.5G", 3 * 2**29),
                                         ("800M", 800 * 2**20), ("64 k", 65536), ("1kib", 1024),
                                         ("1048576", 2**20), (4096, 4096), (np.int64(7), 7)])
def test_sizes_are_bytes_or_binary_units(value, size):
    assert parse_size(value) == size


@pytest.mark.parametrize("value", ["2GB", "1.5", "1.M", "abc", "", "-1M", "0", "0K", 0, -3, 1.5, True, None])
def test_anything_else_is_one_line_naming_the_forms(value):
    with pytest.raises(InputError, match="device_memory") as err:
        parse_size(value)
    assert "\n" not in str(err.value) and ("512MiB" in str(err.value) or "at least one byte" in str(err.value))


def test_the_budget_is_the_device_or_less(cc):
    info = cc.info
    assert device_budget(cc) == DeviceBudget(info.global_mem, info.max_alloc, None)
    assert device_budget(cc, "1M") == DeviceBudget(2**20, 2**20, 2**20)
    assert device_budget(cc, 4 * info.global_mem).total == info.global_mem
    assert [format_size(n) for n in (100, 2**10, 37 * 2**20 + 1, 3 * 2**29)] == ["100 bytes", "1 KiB", "38 MiB",
                                                                                   "1.5 GiB"]


def test_streamed_chunks_equal_the_same_ranges_on_the_device(cc, wv, monkeypatch):
    """Same coefficients, same order, same passes: bit for bit; and each chunk copied from the renderer's own
    table (no host copy of it)."""
    r, packed, copy = clwave.SplatRenderer(wv, device=cc, device_memory=CAP), [], renderer_module.cl.enqueue_copy
    table = r.groups[0]["table"]

    def counted(queue, dest, src, **kw):
        if isinstance(src, np.ndarray) and np.shares_memory(src, table.coef):
            packed.append(len(src))
        return copy(queue, dest, src, **kw)

    monkeypatch.setattr(renderer_module.cl, "enqueue_copy", counted)
    cam = clwave.Camera(30, 20, size=32)
    streamed = clwave.splat(wv, cam, renderer=r)
    chunk, chunks = streamed.meta["chunk_coefficients"], streamed.meta["coefficient_chunks"]
    assert chunks == -(-wv.kept // chunk) >= 3 and max(packed) == chunk and sum(packed) == wv.kept
    assert streamed.meta["device_budget"] == parse_size(CAP) and streamed.meta["coefficients"] == wv.kept
    resident = clwave.SplatRenderer(wv, device=cc)
    acc = resident.begin(cam)
    for first in range(0, wv.kept, chunk):
        acc.splat(first, chunk)
    assert acc.meta(0)["coefficient_chunks"] == 0 and acc.meta(0)["chunk_coefficients"] is None
    assert np.array_equal(streamed.image, acc.image())
    # against one pass of every coefficient: the same float32 terms, added to the framebuffer as ``chunks``
    # partial sums instead of one; the terms of random data cancel (their magnitudes sum to several times
    # the image), so regrouping shows at a few 1e-6 of its maximum: the bound of the other regrouping tests
    whole = clwave.splat(wv, cam, renderer=resident).image
    assert np.abs(streamed.image - whole).max() <= REGROUPED * np.abs(whole).max()


def test_streamed_progressive_frames_equal_those_on_the_device(cc, wv):
    cam = clwave.Camera(-70, -15, size=(24, 40))
    frames = list(clwave.progressive(wv, cam, steps=4, device=cc))
    streamed = list(clwave.progressive(wv, cam, steps=4, device=cc, device_memory=CAP))
    assert [f.coefficients for f in streamed] == [f.coefficients for f in frames]
    assert streamed[-1].meta["coefficient_chunks"] >= 3 and frames[-1].meta["coefficient_chunks"] == 0
    for a, b in zip(streamed, frames):  # chunk boundaries split some frames' passes: another sum order
        assert np.abs(a.image - b.image).max() <= REGROUPED * np.abs(frames[-1].image).max()


def test_streamed_channel_groups(cc):
    """RGBA with one wavelet for colour and another for opacity: two groups, streamed each in turn."""
    data = np.random.default_rng(3).random((16, 16, 16, 4)).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), ["cubic"] * 3 + ["linear"], levels=2)
    cam = clwave.Camera(30, 20, size=32)
    whole = clwave.splat(wv, cam, device=cc)
    streamed = clwave.splat(wv, cam, device=cc, device_memory="6500KiB")  # the linear texel pool is large
    assert len(wv.groups) == 2 and streamed.meta["coefficient_chunks"] >= 2 * 2
    assert np.abs(streamed.image - whole.image).max() <= REGROUPED * np.abs(whole.image).max()


def test_a_budget_below_one_chunk_names_the_least_that_works(cc, wv):
    cam = clwave.Camera(30, 20, size=32)
    with pytest.raises(DeviceMemoryError, match="needs at least") as err:
        clwave.splat(wv, cam, device=cc, device_memory="1MiB")
    message = str(err.value)
    assert "\n" not in message and message.startswith("device_memory=1 MiB is too small")
    assert err.value.cli_message().startswith("--device-memory 1 MiB is too small")
    least = parse_size(message.split("needs at least ")[1].split(" of device")[0])
    result = clwave.splat(wv, cam, device=cc, device_memory=least)
    assert result.meta["chunk_coefficients"] >= renderer_module.MIN_CHUNK
    with pytest.raises(DeviceMemoryError):  # a least, rounded up to a tenth of its unit, not a loose guess
        clwave.splat(wv, cam, device=cc, device_memory=int(0.9 * least))


def test_a_renderer_moves_between_resident_and_streamed_views(cc, wv):
    """A small view keeps every coefficient on the device, a large one under the same cap streams them,
    and the small one after it is the image it was."""
    r = clwave.SplatRenderer(wv, device=cc, device_memory="4MiB")
    small, large = clwave.Camera(30, 20, size=32), clwave.Camera(30, 20, size=64)  # footprints grow with it
    first = clwave.splat(wv, small, renderer=r)
    streamed = clwave.splat(wv, large, renderer=r)
    again = clwave.splat(wv, small, renderer=r)
    assert first.meta["chunk_coefficients"] is None and streamed.meta["coefficient_chunks"] >= 2
    assert np.array_equal(first.image, again.image)


def test_a_budget_below_the_views_framebuffers_and_tile_lists_is_refused_before_its_buffers(cc, wv, monkeypatch,
                                                                                          tmp_path, capsys):
    """A 1024^2 view at one framebuffer (16 MiB) under a 20 MiB cap: its framebuffer, tile ranges, a least chunk of
    coefficients with their splats and the count tables and tile lists at their shares of the budget need more than
    the cap before any footprint table or device buffer is made; one line naming the least cap, and at that cap the
    view gets past this check (to the plan, which counts its footprints too).  The command line says it in its
    words, exit 2."""
    made = []
    for name in ("ViewTables", "ConeTables"):
        monkeypatch.setattr(renderer_module, name, lambda *a, made=made, **k: made.append(a) or 1 / 0)
    cam = clwave.Camera(30, 20, size=1024)
    r = clwave.SplatRenderer(wv, device=cc, device_memory="20MiB", coarse=None)
    with pytest.raises(DeviceMemoryError) as err:
        r.render(cam)
    message = str(err.value)
    assert "\n" not in message and not made and r._tile_lists is None and r._resident is None, message
    # 16 MiB of framebuffer and 4096 tiles' ranges, 1024 coefficients of 64 bytes, over 1 - 1/4 - 1/32 of the budget
    least = (16 * 2**20 + 8 * 64 * 64 + 64 * 1024) / (1 - 1 / 4 - 1 / 32)
    assert message.startswith(f"device_memory=20 MiB is too small: a 1024x1024 view needs at least "
                              f"{format_size(int(least) + 1)} of device memory before its footprints"), message
    named = parse_size(message.split("needs at least ")[1].split(" of device")[0])
    with pytest.raises(ZeroDivisionError):  # past the check: to the footprint tables
        clwave.SplatRenderer(wv, device=cc, device_memory=named, coarse=None).render(cam)
    assert made
    np.save(tmp_path / "v.npy", np.random.default_rng(7).random((16, 16, 16)).astype(np.float32))
    from clwave.cli import main
    assert main(["render", str(tmp_path / "v.npy"), "--method", "splat", "--size", "1024", "--coarse", "0",
                 "--device-memory", "20M", "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--device-memory 20 MiB is too small: a 1024x1024 view needs at least 23 MiB" in err, err
    assert not (tmp_path / "x.png").exists()


def turns_with(stages, other) -> tuple:
    """What the generator of stages ``stages`` returns, ``other(i)`` run between its stages i and i + 1; and how many
    times it ran."""
    between = 0
    while True:
        try:
            next(stages)
        except StopIteration as end:
            return end.value, between
        other(between)
        between += 1


@pytest.mark.parametrize("cap, pairs", [(None, None), (CAP, None), (None, 3000)])
def test_an_image_in_turns_is_the_splat_whatever_the_renderer_splats_between_its_stages(cc, wv, monkeypatch, cap,
                                                                                       pairs):
    """``splat_in_turns`` (a viewer's save, docs/viewer.md §5) with another image of the same renderer, of another size
    each time, splatted between every two of its stages: every coefficient on the device, streamed (a cap), or passes
    split in halves (a pair budget of 3000): bit for bit ``clwave.splat`` with a renderer of its own (the same passes;
    the tile lists and chunks of the image in turns its own, which the images between would write over)."""
    from clwave.splat import stages
    from clwave.splat.renderer import splat_in_turns

    if pairs:
        monkeypatch.setattr(stages.Stages, "pair_budget", lambda self, budget: pairs)
    cam = clwave.Camera(30, 20, size=32)
    expect = clwave.splat(wv, cam, renderer=clwave.SplatRenderer(wv, device=cc, device_memory=cap))
    r = clwave.SplatRenderer(wv, device=cc, device_memory=cap)
    got, between = turns_with(splat_in_turns(r, cam), lambda i: clwave.splat(
        wv, clwave.Camera(40 * i, -10, size=(16 + i % 3, 24)), renderer=r))
    assert between >= 1 + max(1, expect.meta["coefficient_chunks"]) and np.array_equal(got.image, expect.image)
    assert got.meta["coefficient_chunks"] == expect.meta["coefficient_chunks"] and (cap is None) == (
        got.meta["coefficient_chunks"] == 0)
