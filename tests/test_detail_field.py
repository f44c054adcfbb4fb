"""The details' field energy a ``.clw`` file holds for the staged tracer's estimate (clwave/io/detail_field.py,
docs/chunked.md §4, docs/raytracing.md §9): against a midpoint sum of the closed-form field, read back as the
tiers' energy with the coarsest level's replaced, and refused in one line where the file's figure is damaged."""

import h5py
import numpy as np
import pytest

from clwave import WaveletVolume
from clwave.errors import FileFormatError
from clwave.io.summary import detail_energy, detail_field
from clwave.model.wavelet import importance_of
from test_bricks import smooth_volume


@pytest.fixture(scope="module", params=["cubic", "linear"])
def saved(tmp_path_factory, request):
    """Two channels of smooth blobs and a spike, 2 levels; the path and the model."""
    vol = smooth_volume(n=20, channels=2)
    wv = WaveletVolume.from_volume(vol, wavelet=request.param, levels=2).threshold(keep=0.3)
    path = tmp_path_factory.mktemp("field") / "m.clw"
    wv.save(path)
    return path, wv


def coarsest_field_energy(group, level) -> float:
    """NumPy oracle: the energy of the field of ``group``'s level-``level`` details, channels summed, from the
    closed-form prototypes: per pair of bands, per axis the integrals of their functions' products by 4-point
    Gauss-Legendre over each fine cell (the functions' knots lie on whole fine cells at levels >= 1, so a
    product, of degree 2j - 2 on a cell, is integrated exactly)."""
    w, scale = group.wavelet, 2 ** level
    bands = [(b, d) for b, d in zip(group.bands, group.dense_bands()) if b.level == level and b.key != "aaa"]
    ends = [w.offset(letter, level) + scale * (n + w.support(letter)) for b, _ in bands for letter, n in
            zip(b.key, b.shape)]
    nodes, weights = np.polynomial.legendre.leggauss(4)
    cells = np.arange(min(w.offset(letter, level) for letter in "ad"), max(ends))
    t = (cells[:, None] + (nodes + 1) / 2).reshape(-1)
    dt = np.tile(weights / 2, len(cells))

    def basis(letter, n):  # (points, n): the level's normalised functions along one axis
        return w.prototype(letter, (t[:, None] - w.offset(letter, level)) / scale - np.arange(n)) / np.sqrt(scale)

    energy = 0.0
    for b, d in bands:
        for b2, d2 in bands:
            grams = [(basis(p, n) * dt[:, None]).T @ basis(p2, n2) for p, n, p2, n2 in zip(b.key, b.shape, b2.key,
                                                                                         b2.shape)]
            energy += np.einsum("abcq,ABCq,aA,bB,cC->", d, d2, *grams, optimize=True)
    return float(energy)


def test_the_figure_is_the_coarsest_details_field_energy(saved):
    """The first figure against the energy of the field of level L's details from the closed-form functions
    (:func:`coarsest_field_energy`; the writer's synthesis in float32, summed in float64), scaled to the importances'
    convention as the writer scales it; the second
    within a tier's ``2^(1/8)`` of their squared importances."""
    assert_figure_of(*saved)


def test_a_quantised_files_figure_is_of_the_values_stored(saved, tmp_path):
    """With quantised values (some rounding to zero, not stored) the figure is the one of the model read back."""
    path = saved[1].save(tmp_path / "q.clw", quantise="auto")
    read = WaveletVolume.open(path)
    assert read.kept < saved[1].kept  # values rounded away
    assert_figure_of(path, read)


def assert_figure_of(path, wv):
    with h5py.File(path) as h5:
        figures = [h5[f"g{gi}/detail_field"][...] for gi in range(len(wv.groups))]
    for g, figure in zip(wv.groups, figures, strict=True):
        coarsest = slice(g.band_slices()[1].start, g.band_slices()[7].stop)
        importances = np.sum(importance_of(g, None, wv.frame)[coarsest].astype(np.float64) ** 2)
        plain = sum(np.sum(g.values[:, sl].astype(np.float64) ** 2) * np.prod([g.wavelet.norm(c) for c in b.key]) ** 2
                    for b, sl in zip(g.bands[1:8], g.band_slices()[1:8]))
        field = coarsest_field_energy(g, wv.levels)
        assert importances > 0 and field > 0
        assert figure[0] == pytest.approx(field * importances / plain, rel=1e-6)  # synthesized in float32
        assert 2 ** -0.125 <= figure[1] / importances <= 2 ** 0.125


def test_the_details_energy_is_the_tiers_with_the_coarsest_levels_field(saved):
    """detail_field: the finer levels' squared importances (within a tier's 2^(1/8)) plus the coarsest level's
    field energy (here above their importance energy: smooth blobs' details add up, where the test models' cancel)."""
    path, wv = saved
    with h5py.File(path) as h5:
        fields = sum(h5[f"g{gi}/detail_field"][0] for gi in range(len(wv.groups)))
    finer = 0.0
    for g in wv.groups:
        imp = importance_of(g, None, wv.frame).astype(np.float64) ** 2
        finer += imp[g.band_slices()[8].start:].sum()
    assert finer > 0
    assert 2 ** -0.125 <= (detail_field(path) - fields) / finer <= 2 ** 0.125
    assert detail_field(path) > detail_energy(path)


def test_a_file_without_the_figure_reads_none(saved, tmp_path):
    old = tmp_path / "old.clw"
    old.write_bytes(saved[0].read_bytes())
    with h5py.File(old, "r+") as h5:
        del h5["g0/detail_field"]
    assert detail_field(old) is None


@pytest.mark.parametrize("damage, said", [(np.array([np.nan, 1.0]), "not two finite energies"),
                                          (np.array([-1.0, 1.0]), "not two finite energies"),
                                          (np.ones(3), "expected (2,) float64"),
                                          (np.ones(2, np.float32), "expected (2,) float64"),
                                          (np.array([0.0, 1e300]), "more energy than the file's tiers")])
def test_a_damaged_figure_is_refused_in_one_line(saved, tmp_path, damage, said):
    bad = tmp_path / "bad.clw"
    bad.write_bytes(saved[0].read_bytes())
    with h5py.File(bad, "r+") as h5:
        del h5["g0/detail_field"]
        h5["g0/detail_field"] = damage
    with pytest.raises(FileFormatError, match="detail_field") as caught:
        detail_field(bad)
    assert said in str(caught.value) and "\n" not in str(caught.value)
