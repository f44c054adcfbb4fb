"""Alpha's floors of the mixed bricks' pieces (clwave.raytrace.pieces.alpha_floors, docs/raytracing.md §3): found
over each box's shared windows, a few boxes at a time, against the Bernstein coefficients of each cell alone."""

import numpy as np
import pytest

from clwave.model.bspline import wavelet_for
from clwave.raytrace import pieces


def cell_oracle(box, j, parts):
    """(n p, n p, n p): per cell of one box and part, the least Bernstein coefficient, each cell's window taken to
    them by one einsum of the three axes' matrices (pieces.bernstein, row k: coefficient k)."""
    n = np.array(box.shape) - j + 1
    out = np.empty(tuple(n * parts))
    for cell in np.ndindex(*n):
        window = box[tuple(slice(c, c + j) for c in cell)]
        for part in np.ndindex(parts, parts, parts):
            m = [pieces.bernstein(j, q, parts)[:, ::-1] for q in part]
            out[tuple(c * parts + q for c, q in zip(cell, part))] = np.einsum(
                "ai,bj,ck,ijk->abc", m[0], m[1], m[2], window).min()
    return out


@pytest.mark.parametrize("name", ["haar", "linear", "quadratic", "cubic", "quintic"])
def test_floors_of_stacked_boxes_are_each_cells_own(name, monkeypatch):
    """Boxes of signed coefficients with exact zeros (an empty margin's): each cell's floor is its own Bernstein
    coefficients' least (1e-12; the parts of a cell whose floor is negative where ``where`` is set, the cell's
    floor elsewhere), bit for bit the sums of :func:`pieces._cell_floors` on that cell alone (the arithmetic that
    keeps a render's pieces, and so its image, as before), and the same found one box at a time."""
    wav = wavelet_for(name)
    j = wav.order
    rng = np.random.default_rng(7)
    coef = rng.normal(0.3, 1.0, (3, j + 2, j + 3, j + 1))
    coef[coef < -0.4] = 0.0
    n = np.array(coef.shape[1:]) - j + 1
    where = rng.random((3, *n)) < 0.6
    whole = pieces.alpha_floors(coef, wav)
    assert whole.shape == (3, *n)
    cells = np.lib.stride_tricks.sliding_window_view(coef, (j, j, j), axis=(1, 2, 3)).reshape(-1, j, j, j)
    np.testing.assert_array_equal(whole.ravel(), pieces._cell_floors(cells, pieces.bernstein(j)[None, :, ::-1])[:, 0])
    for parts in (1, 2, 3):
        got = pieces.alpha_floors(coef, wav, parts, where)
        for box, mask, floors in zip(coef, where, got):
            cell = cell_oracle(box, j, 1)
            cut, cell = (np.kron(a, np.ones((parts,) * 3)) for a in (mask & (cell < 0), cell))  # per part
            np.testing.assert_allclose(floors, np.where(cut > 0, cell_oracle(box, j, parts), cell), rtol=0, atol=1e-12)
        monkeypatch.setattr(pieces, "CELLS", 1)  # a box at a time
        np.testing.assert_array_equal(pieces.alpha_floors(coef, wav, parts, where), got)
        monkeypatch.undo()
