"""NumPy references of the splatting kernels, one function per stage (tiny inputs only).

Integer stages mirror the kernels' float32 arithmetic step by step (no fused
multiply-add: ``FP_CONTRACT OFF`` in ``cl/common/clw_common.h``), so tests can demand
exact equality; the accumulation is a float64 sum.
"""

from __future__ import annotations

import numpy as np

from ..device.constants import CELL_SNAP, TILE
from ..model.geometry import world_to_fine
from .perspective import quasi_interpolant
from .tables import GATHER_U, LINEAR_U, LINEAR_V


def project(coef, first, band_tex, band_origin, step_col, step_row, tex_box, tex_layer, layers, n):
    """Reference of ``splat_project``: centre, bbox (in the texture's layer), texture id and tile count per splat."""
    f32 = np.float32
    c = np.asarray(coef[first:first + n])
    band = c[:, 3]
    sc, sr, o = step_col[band], step_row[band], band_origin[band]
    k = c[:, :3].astype(f32)
    col = ((o[:, 0] + k[:, 0] * sc[:, 0]) + k[:, 1] * sc[:, 1]) + k[:, 2] * sc[:, 2]
    row = ((o[:, 1] + k[:, 0] * sr[:, 0]) + k[:, 1] * sr[:, 1]) + k[:, 2] * sr[:, 2]
    tex = band_tex[band]
    b = tex_box[np.maximum(tex, 0)]
    width, height = layers[tex_layer[np.maximum(tex, 0), 0], :2].T
    x0 = np.maximum(np.ceil(col + b[:, 0]), f32(0))
    x1 = np.minimum(np.floor(col + b[:, 1]), (width - 1).astype(f32))
    y0 = np.maximum(np.ceil(row - b[:, 3]), f32(0))
    y1 = np.minimum(np.floor(row - b[:, 2]), (height - 1).astype(f32))
    hit = (tex >= 0) & (x0 <= x1) & (y0 <= y1)
    bbox = np.where(hit[:, None], np.stack([x0, y0, x1, y1], 1).astype(np.int32), [0, 0, -1, -1]).astype(np.int32)
    count = np.where(hit, (bbox[:, 2] // TILE - bbox[:, 0] // TILE + 1) * (bbox[:, 3] // TILE - bbox[:, 1] // TILE + 1),
                     0).astype(np.uint32)
    return np.stack([col, row], 1).astype(np.float32), bbox, tex.astype(np.int32), count


def _tiles(box, layer):
    """Tile ids a pixel box (x0, y0, x1, y1) touches, row by row, in layer (width, height, first tile, first pixel)."""
    x0, y0, x1, y1 = (int(v) for v in box)
    tiles_x = -(-int(layer[0]) // TILE)
    if x1 < x0:
        return []
    return [int(layer[2]) + ty * tiles_x + tx for ty in range(y0 // TILE, y1 // TILE + 1)
            for tx in range(x0 // TILE, x1 // TILE + 1)]


def tile_corner(tile, layers) -> tuple:
    """``(layer, x, y)``: the layer a tile id belongs to and the tile's corner pixel in it."""
    layer = int(np.searchsorted(layers[:, 2], tile, side="right")) - 1
    index, tiles_x = tile - int(layers[layer, 2]), -(-int(layers[layer, 0]) // TILE)
    return layer, index % tiles_x * TILE, index // tiles_x * TILE


def count_tiles(bbox, stex, tex_layer, layers, textures, chunk, chunks, tiles):
    """Reference of ``splat_chunk_tiles`` counting: (chunks, tiles * textures) uint32, ``[c, tile * textures + j]``
    counts the splats of chunk c (splats ``c * chunk ..``) with texture j of its layer that touch the tile."""
    hist = np.zeros((chunks, tiles, textures), np.uint32)
    for i, box in enumerate(bbox):
        layer, j = tex_layer[stex[i]]
        for t in _tiles(box, layers[layer]):
            hist[i // chunk, t, j] += 1
    return hist.reshape(chunks, -1)


def bin_by_tile(bbox, stex, tex_layer, layers, tiles):
    """Reference of scan + ``tile_ranges`` and of the order ``splat_chunk_tiles`` places in: ``(ranges, vals)``.

    A stable sort of the (tile, splat) pairs by tile and texture: ``vals[ranges[t, 0]:ranges[t, 1]]``
    are the splats touching tile t, by texture, each texture's in increasing order (importance).
    (The kernels sort by the index within the layer, the same order where each layer's textures
    are consecutive ids, as the renderer makes them.)  :func:`records` turns them into records.
    """
    pairs = [(t, i) for i, box in enumerate(bbox) for t in _tiles(box, layers[tex_layer[stex[i], 0]])]
    tiles_of = np.array([t for t, _ in pairs], np.int64)
    vals = np.array([i for _, i in pairs], np.uint32)
    order = np.lexsort((vals, stex[vals], tiles_of))
    tiles_of, vals = tiles_of[order], vals[order]
    ranges = np.zeros((tiles, 2), np.uint32)
    edges = np.searchsorted(tiles_of, np.arange(tiles + 1))
    ranges[:, 0], ranges[:, 1] = edges[:-1], edges[1:]
    return ranges, vals


def records(ranges, vals, first, centre, bbox, stex, values, layers, channels):
    """Reference of the records ``splat_chunk_tiles`` places (``cl/splat/record.h``): (pairs, 4 * R) uint32.

    Per pair: centre, the bits (texture id; the splat's pixels in the tile, 4 bits each) and
    c_0, then, with more than one channel, c_1..c_3 and 0 (R = 2 uint4s); floats as their bits.
    Perspective centres (col, row, depth, 0) put the depth in the w of the second uint4, always present
    (with every channel's value before it).
    The packing restates ``cl/splat/record.h``; :func:`accumulate` works from ``vals`` and the
    splats' own tables instead, so a wrong layout also shows in the accumulated image.
    """
    perspective = centre.shape[1] == 4
    nc = 1 if channels == 1 and not perspective else 4
    floats = np.zeros((len(vals), 4 * (1 + (nc > 1))), np.float32)
    bits = np.zeros(len(vals), np.uint32)
    for tile, (start, end) in enumerate(ranges):
        _, x, y = tile_corner(tile, layers)
        for k in range(start, end):
            s = vals[k]
            x0, y0, x1, y1 = (int(v) for v in np.clip(bbox[s] - [x, y, x, y], 0, TILE - 1))
            bits[k] = int(stex[s]) | x0 << 16 | x1 << 20 | y0 << 24 | y1 << 28
            floats[k, :2] = centre[s, :2]
            if perspective:
                floats[k, 7] = centre[s, 2]
            floats[k, 3:3 + nc] = values[first + s, :nc]
    out = floats.view(np.uint32)
    out[:, 2] = bits
    return out


def _axis_lookup(pixels, centre_px, centre_tex, steps, count, linear):
    """Texel indices (into the texture with one ring of zeros) and the weight of the second, per pixel.

    Linear: ``t = centre_tex + offset * steps`` in float64, clamped to the zero ring [-1, count], texels i and
    i + 1 with i = min(floor(t), count - 1), the weight of the second t - i (beyond the ring: zeros).
    Nearest: the kernel's float32 ``(centre_tex + 1/2) + offset * steps``, within ``CELL_SNAP`` pixels of a whole
    number that number (``cell_position`` in ``cl/splat/raster.h``), floored; weight 0 on the second."""
    f32 = np.float32
    if linear:
        t = np.clip(centre_tex + (pixels - np.float64(centre_px)) * steps, -1, count)
        i = np.minimum(np.floor(t).astype(int), count - 1)
        return i + 1, i + 2, t - i
    t = (f32(centre_tex) + f32(0.5)) + (pixels.astype(f32) - f32(centre_px)) * f32(steps)
    edge = np.rint(t)
    t = np.where(np.abs(t - edge) <= f32(CELL_SNAP) * f32(steps), edge, t)
    i = np.clip(np.floor(t).astype(int), -1, count) + 1
    return i, i, np.zeros(len(pixels))


def accumulate(ranges, vals, first, centre, bbox, stex, values, textures, layers, channels=4):
    """Reference of ``splat_accumulate`` (float64): footprint samples times c, channels < ``channels``,
    into the framebuffers of ``layers`` one after the other, (pixels, 4).

    ``textures`` are ``(data (nv, nu), centre_u, centre_v, lookup, s_u, s_v)``: per axis, s
    texels per pixel; linear interpolation where the axis' lookup bit is set (u: ``LINEAR_U`` or
    ``GATHER_U``), nearest sample where it is clear.  Image rows go down while v goes up.
    """
    fbs = [np.zeros((h, w, 4)) for w, h, _, _ in layers]
    for layer, s, xs, ys in _tile_pixels(ranges, vals, bbox, layers):
        data, cu, cv, lookup, su, sv = textures[stex[s]]
        nv, nu = data.shape
        tex = np.zeros((nv + 2, nu + 2))  # one ring of zeros outside
        tex[1:-1, 1:-1] = data
        iu0, iu1, fu = _axis_lookup(xs, centre[s, 0], cu, su, nu, lookup & (LINEAR_U | GATHER_U))
        # rows: offset (centre - y) along v, i.e. the same lookup of -y about -centre
        iv0, iv1, fv = _axis_lookup(-ys, -centre[s, 1], cv, sv, nv, lookup & LINEAR_V)
        top = tex[iv0[:, None], iu0] * (1 - fu) + tex[iv0[:, None], iu1] * fu
        bot = tex[iv1[:, None], iu0] * (1 - fu) + tex[iv1[:, None], iu1] * fu
        sample = top * (1 - fv[:, None]) + bot * fv[:, None]
        fbs[layer][ys[:, None], xs[None, :], :channels] += sample[..., None] * values[first + s, :channels]
    return np.concatenate([fb.reshape(-1, 4) for fb in fbs])


def _tile_pixels(ranges, vals, bbox, layers):
    """``(layer, splat, columns, rows)`` of every record in tile order: the splat's pixels in its tile."""
    for tile, (start, end) in enumerate(ranges):
        layer, x, y = tile_corner(tile, layers)
        for s in vals[start:end]:
            x0, y0, x1, y1 = bbox[s]
            xs = np.arange(max(x0, x), min(x1, x + TILE - 1) + 1)
            ys = np.arange(max(y0, y), min(y1, y + TILE - 1) + 1)
            if len(xs) and len(ys):
                yield layer, s, xs, ys


def project_cone(coef, first, band_tex, band_world, band_step, tex_box, tex_layer, layers, layer_slope, cone, n):
    """Reference of ``splat_project_cone`` (``cl/splat/cone.cl``, float64): per splat the centre ``(col, row,
    depth, 0)`` in its layer, bbox, texture id and tile count, and each box's *slack*: how far (pixels) its
    four unclamped edges lie from a whole pixel, below which float32 rounding may move an edge."""
    c = np.asarray(coef[first:first + n])
    band = c[:, 3]
    tex = band_tex[band]
    t = np.maximum(tex, 0)
    x = band_world[band, :3].astype(float) + c[:, :3] * band_step[band, :3].astype(float)
    e, nrm, u, v = (np.asarray(cone[i, :3], float) for i in range(4))
    d = x - e
    depth = -(d @ nrm)
    layer = layers[tex_layer[t, 0]]
    sigma = layer_slope[tex_layer[t, 0], :2].astype(float)
    shown = (tex >= 0) & (depth > 0)
    z = np.where(shown, depth, 1.0)
    col = np.where(shown, (d @ u / z - cone[4, 0]) / sigma[:, 0] + 0.5 * layer[:, 0] - 0.5, 0.0)
    row = np.where(shown, 0.5 * layer[:, 1] - 0.5 - (d @ v / z - cone[4, 1]) / sigma[:, 1], 0.0)
    b = tex_box[t].astype(float)
    pu, pv = 1.0 / (z * sigma[:, 0]), 1.0 / (z * sigma[:, 1])
    edges = np.stack([col + b[:, 0] * pu, col + b[:, 1] * pu, row - b[:, 3] * pv, row - b[:, 2] * pv], 1)
    x0, x1 = np.maximum(np.ceil(edges[:, 0]), 0), np.minimum(np.floor(edges[:, 1]), layer[:, 0] - 1)
    y0, y1 = np.maximum(np.ceil(edges[:, 2]), 0), np.minimum(np.floor(edges[:, 3]), layer[:, 1] - 1)
    hit = shown & (x0 <= x1) & (y0 <= y1)
    bbox = np.where(hit[:, None], np.stack([x0, y0, x1, y1], 1), [0, 0, -1, -1]).astype(np.int32)
    count = np.where(hit, (bbox[:, 2] // TILE - bbox[:, 0] // TILE + 1) * (bbox[:, 3] // TILE - bbox[:, 1] // TILE + 1),
                     0).astype(np.uint32)
    slack = np.abs(edges - np.round(edges)).min(axis=1)
    centre = np.stack([col, row, depth, np.zeros(n)], 1)
    return centre, bbox, tex.astype(np.int32), count, slack


def slope_cells(nodes, count, quasi=False) -> tuple:
    """Reference of ``cone_cells`` (``cl/splat/cone_cells.cl``) for one texture: ``(cells, peaks)``, its nodes
    (K, nv, nu), K = count_u count_v row-major by v, as ``cl/splat/cone.cl`` reads them, one block per cell of the
    slope grid, (cells, nv + 2, nu + 2, 4) float32, the cell's four nodes interleaved per texel (first node, next
    along u, next along v, both) with a zero margin all round; and each node's largest magnitude (K,).  ``quasi``:
    the nodes' quasi-interpolants along the slope axes (:func:`clwave.splat.perspective.quasi_interpolant`)."""
    ku, kv = (int(c) for c in count)
    K, nv, nu = nodes.shape
    x = np.array(nodes, np.float32).reshape(kv, ku, nv, nu)
    if quasi:
        quasi_interpolant(x, (0, 1))
    cells = np.zeros((kv - 1, ku - 1, nv + 2, nu + 2, 4), np.float32)
    for c, (dv, du) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        cells[:, :, 1:-1, 1:-1, c] = x[dv:dv + kv - 1, du:du + ku - 1]
    return cells.reshape(-1, nv + 2, nu + 2, 4), np.abs(x).max(axis=(2, 3)).ravel()


def accumulate_cone(ranges, vals, first, centre, bbox, stex, values, textures, layers, layer_slope, cone,
                    channels=4):
    """Reference of ``splat_accumulate_cone`` (float64), as :func:`accumulate` for perspective views.

    ``textures`` are ``(nodes (K, nv, nu), centre_u, centre_v, 1/h_u, 1/h_v)``: the footprint at each node of
    the slope grid ``cone[4].zw + i / cone[5].xy``, ``i < cone[5].zw`` (row-major by v).  A pixel's ray has
    slopes ``s``; it blends the four nodes around ``s`` bilinearly (edge nodes beyond the grid), each read
    bilinearly (zeros outside) at ``(centre_u, centre_v) + depth sigma (pixel - splat centre) / h``.
    """
    lo, inv, count = np.asarray(cone[4, 2:], float), np.asarray(cone[5, :2], float), cone[5, 2:].astype(int)

    def cell(s, a):  # first node and the next's weight along axis a
        g = np.clip((s - lo[a]) * inv[a], 0, count[a] - 1)
        i = np.minimum(np.floor(g).astype(int), count[a] - 2)
        return i, g - i

    def bilinear(tex, tu, tv):  # tex with a ring of zeros; tu (X,), tv (Y,) in unpadded texels
        iu, iv = np.floor(tu).astype(int), np.floor(tv).astype(int)
        fu, fv = tu - iu, tv - iv

        def at(r, q):  # texel rows r, columns q; the ring beyond
            return tex[np.clip(r + 1, 0, tex.shape[0] - 1)[:, None], np.clip(q + 1, 0, tex.shape[1] - 1)]

        return ((1 - fv)[:, None] * ((1 - fu) * at(iv, iu) + fu * at(iv, iu + 1))
                + fv[:, None] * ((1 - fu) * at(iv + 1, iu) + fu * at(iv + 1, iu + 1)))

    fbs = [np.zeros((h, w, 4)) for w, h, _, _ in layers]
    for layer, s, xs, ys in _tile_pixels(ranges, vals, bbox, layers):
        W, H = (int(a) for a in layers[layer, :2])
        sigma = np.asarray(layer_slope[layer, :2], float)
        nodes, cu, cv, iu_h, iv_h = textures[stex[s]]
        K, nv, nu = nodes.shape
        tex = np.zeros((K, nv + 2, nu + 2))
        tex[:, 1:-1, 1:-1] = nodes
        col, row, depth = (float(a) for a in centre[s, :3])
        reads = np.stack([bilinear(tex[k], cu + (xs - col) * depth * sigma[0] * iu_h,
                                   cv + (row - ys) * depth * sigma[1] * iv_h) for k in range(K)])  # (K, Y, X)
        i_u, w_u = cell(cone[4, 0] + (xs + 0.5 - 0.5 * W) * sigma[0], 0)
        i_v, w_v = cell(cone[4, 1] + (0.5 * H - ys - 0.5) * sigma[1], 1)
        sample = np.zeros((len(ys), len(xs)))
        for dv, dv_w in ((0, 1 - w_v), (1, w_v)):
            for du, du_w in ((0, 1 - w_u), (1, w_u)):
                node = (i_v + dv)[:, None] * count[0] + (i_u + du)[None, :]
                sample += dv_w[:, None] * du_w[None, :] * np.take_along_axis(reads, node[None], 0)[0]
        fbs[layer][ys[:, None], xs[None, :], :channels] += sample[..., None] * values[first + s, :channels]
    return np.concatenate([fb.reshape(-1, 4) for fb in fbs])


def exact_xray(coeffs, order, spacing, origin, view):
    """Exact X-ray image of the fine-level spline ``sum_i c_i N_j(x - i)`` (float64).

    ``coeffs`` (nz, ny, nx[, C]) are the fine B-spline coefficients (``reconstruct()``
    for the approximating model), ``view`` a resolved camera: orthographic (each pixel's line
    along n through its centre) or perspective (each pixel's ray from the eye, ``View.rays``; the
    model must lie in front of the eye).  Each line is cut at every knot plane of the three axes;
    between knots the integrand is a polynomial of degree 3(j - 1), integrated exactly by
    Gauss-Legendre.  An oracle for small volumes: it visits every segment of every ray in NumPy.
    """
    from ..model.bspline import bspline

    c = np.asarray(coeffs, np.float64)
    c = c[..., None] if c.ndim == 3 else c
    shape = np.array(c.shape[:3][::-1], float)  # (nx, ny, nz)
    d = np.array(spacing[::-1], float)
    H, W = view.size
    if view.perspective:
        starts, directions = np.broadcast_to(view.eye, (H * W, 3)), view.rays().reshape(-1, 3)
    else:
        starts, directions = view.pixel_centres().reshape(-1, 3), np.broadcast_to(view.n, (H * W, 3))
    x0 = world_to_fine(starts, order, c.shape[:3], spacing, origin)[:, ::-1]  # (x, y, z), along p = start + t dir
    w = np.asarray(directions) / d
    g = (3 * (order - 1)) // 2 + 1
    nodes, weights = np.polynomial.legendre.leggauss(g)
    knots = []  # t where x_a crosses each integer of the support [0, n_a + j], all pixels at once
    for a in range(3):
        planes = np.arange(0, shape[a] + order + 1)
        rate = np.where(np.abs(w[:, a]) > 1e-14, w[:, a], 0.0)[:, None]
        if np.any(rate):
            with np.errstate(divide="ignore", invalid="ignore"):
                knots.append((planes[None, :] - x0[:, a, None]) / rate)
    knots = np.concatenate(knots, axis=1)
    # a ray along an axis' planes crosses none of them: its crossings there repeat the ray's last one
    last = np.max(np.where(np.isfinite(knots), knots, -np.inf), axis=1, keepdims=True)
    knots = np.sort(np.where(np.isfinite(knots), knots, last), axis=1)  # (P, K); f = 0 outside [first, last]
    mid, half = (knots[:, 1:] + knots[:, :-1]) / 2, (knots[:, 1:] - knots[:, :-1]) / 2
    t = mid[..., None] + half[..., None] * nodes  # (P, K - 1, g)
    x = x0[:, None, None, :] + t[..., None] * w[:, None, None, :]  # fine coordinates of every Gauss point
    base = np.floor(x).astype(int) - order + 1  # first coefficient whose support holds x
    n_int = shape.astype(int)
    # per axis and offset: the B-spline weight, zero where the coefficient lies off the grid
    wts = [[bspline(order, x[..., a] - base[..., a] - o) * ((base[..., a] + o >= 0) & (base[..., a] + o < n_int[a]))
            for o in range(order)] for a in range(3)]
    idx = [[np.clip(base[..., a] + o, 0, n_int[a] - 1) for o in range(order)] for a in range(3)]
    total = np.zeros(x.shape[:3] + (c.shape[3],))
    for i, j, k in np.ndindex(order, order, order):
        total += (wts[0][i] * wts[1][j] * wts[2][k])[..., None] * c[idx[2][k], idx[1][j], idx[0][i]]
    image = np.einsum("pkgc,g,pk->pc", total, weights, half)
    return image.reshape(H, W, -1)
