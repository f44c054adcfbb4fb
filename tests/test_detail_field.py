"""The details' field energy a ``.clw`` file holds for the staged tracer's estimate (clwave/io/detail_field.py,
docs/chunked.md §4, docs/raytracing.md §9): against a midpoint sum of the closed-form field, its tier count against
the file's run table (quantised files too), read back as the tiers' energy with the coarsest level's replaced, and
refused in one line where the file's figure is damaged."""

import h5py
import numpy as np
import pytest

from clwave import RayTracer, TransferFunction, WaveletVolume, phantom
from clwave.errors import FileFormatError
from clwave.io.summary import detail_energy, detail_levels
from clwave.model.chunked import tier_energy, tiers_of
from clwave.model.wavelet import band_importance, importance_of
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
    convention as the writer scales it; the second within a tier's ``9/8`` of their squared importances (3 mantissa
    bits: an importance just under 1.125 is counted 1.125, 0.889 of its square)."""
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
        assert 8 / 9 <= figure[1] / importances <= 9 / 8


def test_the_details_energy_is_the_tiers_with_the_coarsest_levels_field(saved):
    """detail_levels: the finer levels' squared importances (within a tier's 9/8) plus the coarsest level's
    field energy (here above their importance energy: smooth blobs' details add up, where the test models' cancel)."""
    path, wv = saved
    with h5py.File(path) as h5:
        fields = sum(h5[f"g{gi}/detail_field"][0] for gi in range(len(wv.groups)))
    finer = 0.0
    for g in wv.groups:
        imp = importance_of(g, None, wv.frame).astype(np.float64) ** 2
        finer += imp[g.band_slices()[8].start:].sum()
    assert finer > 0
    coarsest, rest = detail_levels(path)  # the two parts apart: the X-ray term weighs them unequally
    assert coarsest == pytest.approx(fields, rel=1e-12) and 8 / 9 <= rest / finer <= 9 / 8
    assert coarsest + rest > detail_energy(path)


def run_table_energies(path, group) -> np.ndarray:
    """NumPy oracle: the coarsest level's and the finer levels' details in a file's run table (``g<i>/runs``, each
    run's positions its differences summed from 0), each row counted at its tier's bounds' product (the float32s
    whose top 12 bits are the tier and the next), per group of the model ``group`` lists the bands of."""
    out = []
    with h5py.File(path) as h5:
        for gi, bands in enumerate(group):
            runs, deltas, energies = h5[f"g{gi}/runs"][...], h5[f"g{gi}/positions"][...], np.zeros(2)
            for tier, start, rows in runs[runs[:, 0] >= 0]:
                positions = np.cumsum(deltas[start:start + rows])
                lo, hi = (np.array([tier, tier + 1], np.uint32) << 20).view(np.float32).astype(np.float64)
                finer = positions >= bands[8].start  # level L's seven detail bands come before
                energies += lo * hi * np.array([np.sum(~finer), np.sum(finer)])
            out.append(energies)
    return np.array(out)


@pytest.fixture(scope="module")
def hydrogen():
    """Hydrogen 48^3 RGBA, cubic, 3 levels, 5 % kept."""
    rgba = TransferFunction.preset("hydrogen").classify(phantom("hydrogen", 48))
    return WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3).threshold(keep=0.05)


@pytest.mark.parametrize("quantise", [3.0, 5.0, 8.0])
def test_a_quantised_files_tier_count_is_its_run_tables(hydrogen, tmp_path, quantise):
    """The run table holds the tiers of the values before rounding, and rounding moves them across tiers (here the
    rounded values' count of the coarsest level is 1.03-1.25 of the whole table's): the second figure is the table's
    count of the coarsest level, so that detail_field is the table's finer levels plus the field, and the staged
    tracer opens the file."""
    path = hydrogen.save(tmp_path / "q.clw", quantise=quantise)
    tables = run_table_energies(path, [g.bands for g in hydrogen.groups])
    with h5py.File(path) as h5:
        figures = np.array([h5[f"g{gi}/detail_field"][...] for gi in range(len(hydrogen.groups))])
    assert np.all(tables > 0)
    np.testing.assert_allclose(figures[:, 1], tables[:, 0], rtol=1e-12)
    assert sum(detail_levels(path)) == pytest.approx(tables[:, 1].sum() + figures[:, 0].sum(), rel=1e-12)
    assert 0 < RayTracer.open(path).missing < 1


def test_a_float_files_tier_count_is_unchanged(hydrogen, tmp_path):
    """Unquantised, the run table's tiers are those of the stored values: the second figure is, bit for bit, their
    tiers' count band by band as the figure was first written (from the values), and the table's."""
    path = hydrogen.save(tmp_path / "f.clw")
    read = WaveletVolume.open(path)
    with h5py.File(path) as h5:
        figures = np.array([h5[f"g{gi}/detail_field"][1] for gi in range(len(read.groups))])
    for g, figure in zip(read.groups, figures, strict=True):
        first = 0.0
        for band, dense in zip(g.bands[1:8], g.dense_bands()[1:8]):
            imp = band_importance(g.wavelet, band, dense.reshape(-1, dense.shape[-1]).T, None, None, None)
            first += float(np.sum(tier_energy(tiers_of(imp[imp > 0]))))
        assert figure == first > 0
    np.testing.assert_allclose(figures, run_table_energies(path, [g.bands for g in read.groups])[:, 0], rtol=1e-12)


def test_a_file_without_the_figure_reads_none(saved, tmp_path):
    old = tmp_path / "old.clw"
    old.write_bytes(saved[0].read_bytes())
    with h5py.File(old, "r+") as h5:
        del h5["g0/detail_field"]
    assert detail_levels(old) is None


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
        detail_levels(bad)
    assert said in str(caught.value) and "\n" not in str(caught.value)
