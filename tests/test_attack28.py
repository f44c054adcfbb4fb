"""The command line's option values and the viewer's routes under hostile input (docs/known-gaps.md §15,
attack28): each failure class found, pinned by one case.  Every refusal is one line on stderr, exit 2, before the
input is read where the value alone is wrong (a missing input file then is never reached) and with no file left."""

import asyncio

import aiohttp
import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.view import view
from clwave.view.server import HEADERS

MISSING = "no-such-volume.npy"  # read after the options are checked: a value refused first never reaches it


def refused(capsys, argv, words):
    """``clwave argv`` exits 2 with one line naming ``words``."""
    assert main(argv) == 2, argv
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("clwave: error: ") and words in err[0], (argv, err)


@pytest.fixture(scope="module")
def volume(tmp_path_factory):
    path = tmp_path_factory.mktemp("attack28") / "v.npy"
    np.save(path, np.random.default_rng(0).random((16, 17, 18), np.float32))
    return str(path)


@pytest.mark.parametrize("value", ["1e308", "1e-320", "1e300,1,1", "1e19"])
def test_a_spacing_outside_the_world_lengths_is_one_line_for_info_and_before_the_read(capsys, volume, value):
    """info echoed --spacing 1e308 into an internal error (OverflowError), 1e-320 into another (math domain error);
    render accepted 1e19 until the volume was made.  WORLD_RANGE bounds a voxel: 1e-18 .. 1e18."""
    refused(capsys, ["info", volume, f"--spacing={value}"], "--spacing")
    refused(capsys, ["render", MISSING, f"--spacing={value}", "-o", "x.png"], "from 1e-18 to 1e+18")


@pytest.mark.parametrize("option, value", [("--subtract", "nan"), ("--nan", "inf"), ("--chunks", "-1")])
def test_info_refuses_the_reading_options_the_commands_refuse(capsys, volume, option, value):
    """info FILE echoed them as "applied as the values are read" (--subtract nan), never checking them."""
    refused(capsys, ["info", volume, f"{option}={value}"], option)


@pytest.mark.parametrize("option", ["--subtract", "--nan"])
def test_a_value_beyond_float32_is_refused_before_the_read_and_by_load(capsys, volume, option):
    """--subtract 1e308 made every voxel inf: NumPy's overflow warning, then a line blaming the volume's values."""
    refused(capsys, ["render", MISSING, f"{option}=1e39", "-o", "x.png"], f"{option} 1e+39 must be within float32")
    with pytest.raises(clwave.InputError, match=f"{option[2:]}=-1e\\+308 must be within float32's range"):
        clwave.load(volume, **{option[2:]: -1e308})


@pytest.mark.parametrize("value", ["1e-320", "1e308"])
def test_an_opacity_unit_outside_the_world_lengths_is_refused(capsys, value):
    """--opacity-unit 1e-320 made every opacity inf: a nearly-opaque warning, then "non-finite voxel values"."""
    refused(capsys, ["compress", MISSING, "--tf", "hydrogen", f"--opacity-unit={value}", "-o", "x.clw"],
            "--opacity-unit")
    with pytest.raises(clwave.InputError, match="opacity unit"):
        clwave.TransferFunction.preset("hydrogen", opacity_unit=float(value))


def test_a_quantisation_bound_whose_step_overflows_is_refused_and_writes_nothing(capsys, tmp_path):
    """--quantise 1e308: a step of inf was written, then the file's own read refused it, naming a temporary file."""
    out = tmp_path / "q.clw"
    refused(capsys, ["compress", "phantom:hydrogen:16", "--quantise", "1e308", "-o", str(out)],
            "--quantise 1e+308 is too large")
    assert list(tmp_path.iterdir()) == []


def test_every_response_of_the_viewer_carries_its_headers_refusals_too():
    """A 403, 404, 405, 400 or 413 came without no-store, nosniff, the CSP or no-referrer (the page's did)."""
    async def go(v):
        base, token = v.url.split("/?")[0], v.server.token
        requests = [("GET", "/viewer.js", b"", 403), ("GET", f"/nothing?token={token}", b"", 404),
                    ("GET", f"/export?token={token}", b"", 405), ("POST", f"/export?token={token}", b"[]", 400),
                    ("POST", f"/image?token={token}", b"x" * 10_000, 413), ("GET", f"/?token={token}", b"", 200)]
        async with aiohttp.ClientSession() as s:
            for method, path, body, status in requests:
                async with s.request(method, base + path, data=body) as r:
                    assert r.status == status, path
                    assert {k: r.headers.get(k) for k in HEADERS} == HEADERS, (status, path)

    with view(clwave.phantom("hydrogen", n=16), size=32, keep=0.2) as v:
        asyncio.run(go(v))


def test_a_footprint_band_past_any_texture_cap_is_refused_before_the_read(capsys):
    """--omega-s 1e308 overflowed the sample count (an internal error); 1e3 took 92 s and 4.2 GB at 32x32."""
    refused(capsys, ["render", MISSING, "--omega-s", "1e308", "-o", "x.png"], "--omega-s 1e+308 must be a positive "
                                                                            "band up to 10000")
    with pytest.raises(clwave.InputError, match="omega_s=1e\\+23 must be a positive band up to 10000"):
        clwave.splat(clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=8), levels=1), clwave.Camera(size=8),
                     omega_s=1e23)


@pytest.mark.parametrize("option, value", [("--extent", "1e19"), ("--distance", "1e308")])
def test_a_camera_farther_than_the_world_lengths_is_refused_before_the_read(capsys, option, value):
    """--perspective --distance 1e308: the ray tracer hung (killed after 120 s), progressive's splatting divided by
    zero (an internal error)."""
    refused(capsys, ["render", MISSING, "--perspective" if option == "--distance" else "--fit=sphere", option, value,
                     "-o", "x.png"], f"{option} {float(value):g} must be a positive world")
    with pytest.raises(clwave.InputError, match="up to 1e\\+18"):
        clwave.Camera(perspective=True, distance=float(value))


def test_a_threshold_past_float32_keeps_the_approximation_without_numpys_warning(recwarn):
    """threshold=1e308 (or --noise 1e308) was compared with the float32 importances after a cast: NumPy's "overflow
    encountered in cast" on stderr before the result, which is right: no detail above it."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=2)
    kept = wv.threshold(threshold=1e308)
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]
    approximation = sum(np.count_nonzero(np.any(g.values[:, :g.band_slices()[0].stop] != 0, axis=0)) for g in wv.groups)
    assert kept.kept == approximation > 0


def test_a_host_that_names_no_interface_is_refused_naming_the_host(capsys):
    """--host '' bound every interface and printed "http://:PORT/?token=..."; a name that does not resolve was told to
    choose another --port, and (orient29) only once the volume was read and transformed: now before any work (a
    missing input is not reached), and so is an address of another machine (TEST-NET-1)."""
    refused(capsys, ["view", MISSING, "--host", ""], "--host '' must name an interface")
    for host in ("nan", "192.0.2.1"):
        refused(capsys, ["view", MISSING, "--host", host], f"cannot listen on {host} (")
        line = rf"^cannot listen on {host} \(.+\); host= must name an interface of this machine: 127.0.0.1 \(the " \
            r"default\) or one that others reach$"
        with pytest.raises(clwave.InputError, match=line):
            view(clwave.phantom("hydrogen", n=8), size=16, host=host).close()


def test_an_empty_path_is_refused_not_read_or_written_as_the_current_folder(capsys, tmp_path, monkeypatch):
    """Path("") is ".": `clwave render ""` read the current folder as slices, `progressive -o "" --force` wrote its
    frames into it."""
    monkeypatch.chdir(tmp_path)
    refused(capsys, ["render", "", "-o", "a.png"], "the input '' names no file or folder")
    with pytest.raises(clwave.InputError, match="path '' names no file"):
        clwave.load("")
    refused(capsys, ["render", "phantom:hydrogen:8", "-o", ""], "-o '' names no file")
    refused(capsys, ["progressive", "phantom:hydrogen:8", "-o", "", "--force"], "-o '' names no folder")
    assert list(tmp_path.iterdir()) == []


def test_a_pose_table_that_is_no_regular_file_is_not_called_missing(capsys, tmp_path):
    """A folder (or FIFO, or device) given as --poses was "does not exist"."""
    refused(capsys, ["drr", "phantom:hydrogen:8", "--poses", str(tmp_path), "-o", str(tmp_path / "d.npy")],
            "is not a regular file")
