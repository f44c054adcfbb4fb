"""Large and slightly magnified splatted images (docs/splatting.md §2, known-gaps §3): phase planes where a pixel
spans between half a texel and two, against the exact line integrals."""

import numpy as np
import pytest

import clwave
from clwave.splat import tables as tables_module
from clwave.splat.reference import exact_xray
from clwave.splat.tables import GATHER_U, LINEAR_U, ViewTables


@pytest.fixture(scope="module")
def data():
    return np.random.default_rng(7).random((16, 16, 16)).astype(np.float32)


def _pool(wv, cam):
    return ViewTables(wv, 0, [(cam.view(wv), None)])


@pytest.mark.parametrize("family, tol, angles, spacing", [
    (family, tol, angles, spacing) for family, tol in (("cubic", 1e-3), ("linear", 2e-3), ("haar", 1e-2))
    for angles, spacing in (((30, 20), (1.0, 1.0, 1.0)), ((-70, -15), (2.0, 1.0, 0.5)))] + [
    ("quintic", 1e-3, (30, 20), (1.0, 1.0, 1.0))])  # quintic's exact integrals are slow: one view, as test_splat's
def test_slightly_magnified_views_read_phase_planes_within_the_exact_bound(cc, data, monkeypatch, family, tol,
                                                                          angles, spacing):
    """Pixels of 1/12 and 1/28 of the finest spacing, where the band asks for between half a texel and two a pixel:
    the textures are sampled at 1/P pixel, P = ceil(s) (1 or 2), read from phase planes (not gathered per pixel, a
    pixel update 5-6x dearer on PoCL), hold at most 4x the texels of the band's own (gathered) sampling, and the
    image stays within the magnified views' tolerances of the exact line integrals."""
    vol = clwave.Volume(data, spacing=spacing)
    wv = clwave.WaveletVolume.from_volume(vol, family, levels=2)
    magnified = 0
    for extent in (8 / 3, 8 / 7):  # 32 pixels of 1/12 and 1/28 of d_min
        cam = clwave.Camera(*angles, size=32, extent=extent * min(spacing))
        planes = _pool(wv, cam)
        rates = [s for band, s in planes.texels_per_pixel.items() if planes.textures[band] is not None]
        if "cells" not in planes.samplings[0]:  # Haar cells keep their nearest lookup along the cell axis
            assert all(lookup & LINEAR_U for lookup in planes.tex_int[:, 3])
        assert all(isinstance(s, int) for s in rates)
        with monkeypatch.context() as m:  # the rule before: every rate under 2 gathered at the band's texel
            m.setattr(tables_module, "PHASE_PLANES_FROM", 2.0)
            gathered = _pool(wv, cam)
        raw = [s for band, s in gathered.texels_per_pixel.items() if gathered.textures[band] is not None]
        assert sum(bool(lookup & GATHER_U) for lookup in gathered.tex_int[:, 3]) == sum(s < 2 for s in raw)
        magnified += sum(s < 2 for s in raw)
        assert rates == [int(np.ceil(s)) for s in raw]
        assert planes.texels.size <= 4 * gathered.texels.size + 4096  # 2x per axis at most, beside margins
        exact = exact_xray(wv.reconstruct().data, wv.groups[0].wavelet.order, vol.spacing, vol.origin, cam.view(vol))
        assert np.abs(clwave.splat(wv, cam, device=cc).image - exact).max() <= tol * np.abs(exact).max()
    assert magnified  # the views reached rates under 2


def test_render_draws_8_bit_pictures_with_a_coarse_default_and_raw_values_exactly(tmp_path, capsys):
    """``clwave render`` (splat) writing an 8-bit picture only takes ``coarse=EIGHT_BIT_COARSE`` unless ``--coarse``
    is given (0: off): its PNG is the API's image at that tolerance; with ``--raw`` the float32 values (and the PNG
    beside them) are the exact render's, and ``--coarse 0`` or a window of its own draws the PNG exactly; a 16-bit PNG
    and a float TIFF are drawn exactly."""
    import json

    import imageio.v3 as iio

    from clwave.cli import main
    from clwave.cli.render import EIGHT_BIT_COARSE

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("shepp-logan", 32), levels=3).threshold(keep=0.1)
    camera = clwave.Camera(30, 20, size=128)
    coarse, exact = (clwave.splat(wv, camera, coarse=c) for c in (EIGHT_BIT_COARSE, None))
    assert max(coarse.meta["framebuffers"]) > 1  # the default draws coarse bands here
    assert np.abs(coarse.image - exact.image).max() <= EIGHT_BIT_COARSE * exact.image.max()
    assert np.abs(coarse.to_uint8().astype(int) - exact.to_uint8()).max() == 1  # a level at most, and not none
    argv = ["render", "phantom:shepp-logan:32", "--levels", "3", "--keep", "0.1", "--size", "128"]
    for name, extra, want in (("default", [], coarse), ("raw", ["--raw", str(tmp_path / "raw.npy")], exact),
                              ("off", ["--coarse", "0"], exact), ("window", ["--window", "0,8"], exact)):
        png = tmp_path / f"{name}.png"
        assert main([*argv, "-o", str(png), *extra]) == 0, capsys.readouterr().err
        assert np.array_equal(iio.imread(png), want.to_uint8((0, 8) if name == "window" else "auto"))
    assert np.array_equal(np.load(tmp_path / "raw.npy"), exact.image)
    for name, extra, want in (("8", [], EIGHT_BIT_COARSE), ("16", ["--bit-depth", "16"], None), ("tif", [], None)):
        out = tmp_path / (f"p{name}.tif" if name == "tif" else f"p{name}.png")
        assert main([*argv, "-o", str(out), *extra, "--stats", str(tmp_path / f"{name}.json")]) == 0
        assert json.loads((tmp_path / f"{name}.json").read_text())["coarse"] == want, name  # 16 bits, float: exact
