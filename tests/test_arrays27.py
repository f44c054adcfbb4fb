"""Arrays in, images out (arrays27, after trial27): an xarray DataArray is read by its dims' names and coordinates,
never by position alone; a Dask one stays lazy; view() takes every array Volume takes; the render functions refuse an
array naming the two calls; a transfer function is taken as a preset name or a matplotlib colormap wherever one is.
Each against an answer made by hand: the array transposed and flipped with NumPy, the spacing and centre written out,
matplotlib's colours."""

import matplotlib
import numpy as np
import pytest
import xarray as xr
from dask.callbacks import Callback

import clwave
from clwave.view import as_model

SHAPE = (6, 7, 8)  # z, y, x
STEPS = (0.5, 1.0, 2.0)  # dz, dy, dx
START = (-1.0, 3.0, 10.0)  # the first z, y, x coordinate


@pytest.fixture(scope="module")
def zyx():
    """A (z, y, x) volume, different along every axis, and its coordinates."""
    data = np.random.default_rng(27).random(SHAPE).astype(np.float32)
    coords = {a: s0 + d * np.arange(n) for a, s0, d, n in zip("zyx", START, STEPS, SHAPE)}
    return data, coords


def by_hand():
    """The spacing and origin (centre, x y z) of the coordinates, written out."""
    centre = [s0 + d * (n - 1) / 2 for s0, d, n in zip(START, STEPS, SHAPE)]
    return STEPS, tuple(centre[::-1])


class Computes(Callback):
    """Counts the Dask computations run while it is active."""

    def __init__(self):
        super().__init__()
        self.runs = 0

    def _start(self, dsk):
        self.runs += 1


def test_reversed_dims_are_put_in_z_y_x_order_and_coordinates_give_spacing_origin_and_unit(zyx):
    data, coords = zyx
    xa = xr.DataArray(data, dims=("z", "y", "x"), coords=coords, attrs={"units": "mm"})  # the values' unit
    for name in "zyx":
        xa[name].attrs["units"] = "millimetre"
    vol = clwave.Volume(xa.transpose("x", "y", "z"))  # until arrays27 read by position: mirrored, spacing 1
    spacing, origin = by_hand()
    assert vol.shape == SHAPE and vol.spacing == spacing and vol.origin == pytest.approx(origin, abs=1e-12)
    assert vol.unit == "mm"
    np.testing.assert_array_equal(vol.data, data)
    cf = clwave.Volume(xa.rename(x="lon", y="lat", z="height").transpose("lat", "height", "lon"))
    assert (cf.spacing, cf.unit) == (spacing, "mm")
    np.testing.assert_array_equal(cf.data, data)
    assert clwave.Volume(xa.assign_attrs(units="K")).unit == "mm"  # the DataArray's own units are its values'
    assert clwave.Volume(xr.DataArray(data)).spacing == (1.0, 1.0, 1.0)  # xarray's dim_0, ... : by position


@pytest.mark.opencl
def test_an_xarray_with_reversed_dims_splats_as_the_array_transposed_by_hand(zyx):
    data, coords = zyx
    xyz = np.ascontiguousarray(data.transpose(2, 1, 0))
    xa = xr.DataArray(xyz, dims=("x", "y", "z"), coords=coords)
    spacing, origin = by_hand()
    expected = clwave.WaveletVolume.from_volume(clwave.Volume(xyz.transpose(2, 1, 0), spacing=spacing, origin=origin),
                                                levels=1)
    model = clwave.WaveletVolume.from_volume(xa, levels=1)
    camera = clwave.Camera(30, 20, size=24)
    np.testing.assert_array_equal(clwave.splat(model, camera).image, clwave.splat(expected, camera).image)
    assert expected.spacing == model.spacing and expected.origin == model.origin


def test_decreasing_coordinates_and_depth_reverse_their_axes(zyx):
    data, coords = zyx
    falling = dict(coords, y=coords["y"][::-1])  # e.g. latitude north to south
    vol = clwave.Volume(xr.DataArray(data, dims=("z", "y", "x"), coords=falling))
    np.testing.assert_array_equal(vol.data, data[:, ::-1, :])
    assert vol.spacing == STEPS and vol.origin == pytest.approx(by_hand()[1], abs=1e-12)
    yx = {"y": coords["y"], "x": coords["x"]}
    depth = clwave.Volume(xr.DataArray(data, dims=("depth", "y", "x"), coords=dict(yx, depth=coords["z"])))
    np.testing.assert_array_equal(depth.data, data[::-1])  # depth points down, z up (CF)
    assert depth.origin[2] == pytest.approx(-by_hand()[1][2])
    up = xr.DataArray(coords["z"], dims="depth", attrs={"positive": "up"})
    np.testing.assert_array_equal(clwave.Volume(xr.DataArray(data, dims=("depth", "y", "x"),
                                                             coords=dict(yx, depth=up))).data, data)


def test_a_channel_dim_goes_last_and_a_cf_axis_names_a_dim(zyx):
    data, coords = zyx
    rgb = np.stack([data, 2 * data, 3 * data])  # (c, z, y, x)
    xa = xr.DataArray(rgb, dims=("band", "row", "column", "slice"),  # named by their coordinates' CF axis
                      coords={"row": xr.DataArray(coords["z"], dims="row", attrs={"axis": "Z"}),
                              "column": xr.DataArray(coords["y"], dims="column", attrs={"axis": "Y"}),
                              "slice": xr.DataArray(coords["x"], dims="slice", attrs={"axis": "X"})})
    vol = clwave.Volume(xa)
    assert vol.channels == 3 and vol.spacing == STEPS
    np.testing.assert_array_equal(vol.data, np.moveaxis(rgb, 0, -1))


def test_an_xarray_over_dask_stays_lazy_in_volume_and_view(zyx):
    data, coords = zyx
    xa = xr.DataArray(data.transpose(2, 1, 0), dims=("x", "y", "z"), coords=coords).chunk(4)
    with Computes() as computes:
        vol = clwave.Volume(xa)
    assert computes.runs == 0 and vol.chunked  # until arrays27: computed whole, an ndarray
    with Computes() as computes:
        np.testing.assert_array_equal(vol.data.compute(), data)
    assert computes.runs == 1  # the counter counts
    spacing, origin = by_hand()
    expected = as_model(clwave.Volume(xa.data.transpose(2, 1, 0), spacing=spacing, origin=origin), keep=0.3)
    points = np.array([[10.0, 5.0, 0.0], [14.0, 6.0, 0.5], [20.0, 8.0, 1.0]])
    for given in (xa, xa.data.transpose(2, 1, 0)):  # until arrays27 view() refused both ("not DataArray", "not Array")
        with clwave.view(given, size=16, keep=0.3) as viewer:
            served = viewer.server.wv
        assert served.shape == SHAPE and served.kept == expected.kept
    np.testing.assert_array_equal(as_model(xa, keep=0.3).evaluate(points), expected.evaluate(points))


def test_spacing_given_wins_and_says_so_where_the_coordinates_differ(zyx):
    data, coords = zyx
    xa = xr.DataArray(data, dims=("z", "y", "x"), coords=coords)
    with pytest.warns(clwave.ClwaveWarning, match=r"spacing=\(1.0, 1.0, 1.0\) given places the DataArray's voxels, "
                                                  r"not its z, y, x coordinates \(steps \(0.5, 1.0, 2.0\)\)"):
        vol = clwave.Volume(xa, spacing=1.0)
    assert vol.spacing == (1.0, 1.0, 1.0) and vol.origin == (0.0, 0.0, 0.0) and vol.unit is None
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert clwave.Volume(xa, spacing=STEPS, origin=(1, 2, 3)).origin == (1.0, 2.0, 3.0)  # agreeing: no warning


@pytest.mark.parametrize("make, words", [
    (lambda d, c: xr.DataArray(d, dims=("time", "y", "x")), "name no axis clwave knows in 'time'"),
    (lambda d, c: xr.DataArray(d, dims=("y", "lat", "x")), "dims 'y', 'lat' both name its y axis"),
    (lambda d, c: xr.DataArray(d, dims=("y", "x", "c")), "name no z axis"),
    (lambda d, c: xr.DataArray(d, dims=("z", "y", "x"), coords=dict(c, x=c["x"] ** 2)),
     "x coordinate is not evenly spaced"),
    (lambda d, c: xr.DataArray(d, dims=("z", "y", "x"), coords=dict(c, y=np.full(7, 2.5))),
     "y coordinate has one value at every voxel, no step: give spacing="),  # review28: "steps from 0 to 0"
    (lambda d, c: xr.DataArray(d, dims=("z", "y", "x"), coords={"z": c["z"], "y": c["y"]}),
     "coordinates on some of its axes but not on x"),
    (lambda d, c: xr.DataArray(d, dims=("z", "y", "x"), coords=c).assign_coords(
        x=xr.DataArray(c["x"], dims="x", attrs={"units": "um"})), "coordinates (z, y, x) are in different units"),
    (lambda d, c: xr.Dataset({"rho": xr.DataArray(d, dims=("z", "y", "x"))}), "an xarray Dataset of the variables rho"),
])
def test_what_cannot_be_placed_is_refused_in_one_line_naming_the_fix(zyx, make, words):
    with pytest.raises(clwave.InputError) as err:
        clwave.Volume(make(*zyx))
    message = str(err.value)
    assert words in message and "\n" not in message
    assert any(fix in message for fix in ("rename", "spacing=", "isel", "ds[name]"))


def test_render_functions_refuse_an_array_naming_the_two_calls(zyx):
    data, _ = zyx
    camera = clwave.Camera(size=8)
    for render, given, name in [(clwave.splat, data, "numpy.ndarray"),
                                (clwave.raytrace, xr.DataArray(data).chunk(4).data, "dask.array.core.Array"),
                                (clwave.splat, clwave.Volume(data), "clwave.Volume")]:
        with pytest.raises(clwave.InputError) as err:
            render(given, camera)
        assert str(err.value).split(": ", 1)[0].endswith(f"needs a clwave.WaveletVolume (a model), got {name}")
        assert ".threshold(keep=0.05), and render it" in str(err.value) and "clwave.view(" in str(err.value)


def test_from_colormap_takes_matplotlibs_colours_and_the_grey_ramp():
    cmap = matplotlib.colormaps["viridis"]
    tf = clwave.TransferFunction.from_colormap(cmap, window=(0.0, 10.0))
    for value in (0.0, 3.0, 10.0):  # at the colormap's own colours (256 of them, 3/10 between two)
        t = value / 10
        rgb, alpha = tf([value])
        i = t * 255
        lo, hi = int(np.floor(i)), min(int(np.floor(i)) + 1, 255)
        expected = cmap(lo)[:3] if lo == hi else np.add(np.multiply(cmap(lo)[:3], hi - i), np.multiply(cmap(hi)[:3],
                                                                                                        i - lo))
        np.testing.assert_allclose(rgb[0], expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(alpha[0], 0.05 * t, rtol=1e-12)
    assert clwave.TransferFunction.from_colormap("viridis") == clwave.TransferFunction.from_colormap(cmap)
    with pytest.raises(clwave.InputError, match=r"TransferFunction.from_colormap\('viridis'\)"):
        clwave.TransferFunction.preset("viridis")
    with pytest.raises(clwave.InputError) as err:  # a typo is no colormap: no from_colormap named (review28)
        clwave.TransferFunction.preset("ct-bones")
    assert str(err.value).endswith("choose one of ct-bone, ct-soft-tissue, mri, hydrogen, grey, brightfield, photo")
    with pytest.raises(clwave.InputError, match=r"^'ct-bones' is no matplotlib colormap"):
        clwave.TransferFunction.from_colormap("ct-bones")


@pytest.mark.opencl
def test_a_preset_name_and_a_colormap_are_taken_wherever_a_transfer_function_is(zyx):
    data, _ = zyx
    grey = clwave.TransferFunction.preset("grey")
    model = clwave.WaveletVolume.from_volume(data, levels=1, transfer_function="grey")
    assert model.transfer_function == grey.to_dict()
    camera = clwave.Camera(30, 20, size=12)
    expected = clwave.raytrace(model, camera, transfer_function=grey, tolerance=1e-2).image
    np.testing.assert_array_equal(clwave.raytrace(model, camera, transfer_function="grey", tolerance=1e-2).image,
                                  expected)
    cmap = matplotlib.colormaps["magma"]
    np.testing.assert_array_equal(clwave.raytrace(model, camera, transfer_function=cmap, tolerance=1e-2).image,
                                  clwave.raytrace(model, camera, tolerance=1e-2,
                                                  transfer_function=clwave.TransferFunction.from_colormap(cmap)).image)
    assert as_model(data, keep=0.5, tf=cmap).transfer_function["name"] == "magma"
    with pytest.raises(clwave.InputError) as err:
        clwave.raytrace(model, camera, transfer_function={0.0: (0, 0, 0, 0), 1.0: (1, 1, 1, 1)})
    assert "or the dict of TransferFunction.to_dict(), got a dict without 'points': make one with " \
           "TransferFunction([(value, r, g, b, opacity), ...]), .preset(name)" in str(err.value)  # review28
    with pytest.raises(clwave.InputError, match=r"got numpy\.ndarray: make one with"):
        clwave.raytrace(model, camera, transfer_function=np.zeros((2, 5)))


@pytest.mark.parametrize("opacity", [(0.0, -1.0), (-0.1, 0.05), (0.0, float("nan")), (0.0, float("inf"))])
def test_from_colormap_refuses_an_opacity_by_its_argument(opacity):
    """(0, -1) was refused as "opacity -0.00392157 of point 1 is negative", a row the caller never wrote (review28)."""
    with pytest.raises(clwave.InputError) as err:
        clwave.TransferFunction.from_colormap("gray", opacity=opacity)
    assert str(err.value).startswith(f"opacity={opacity!r} must be two opacities") and "point" not in str(err.value)


def test_from_colormap_refuses_what_is_no_colormap_of_one_variable_in_one_line():
    """A bivariate colormap came out of matplotlib as "ValueError: For a `BivarColormap` the data must have a first
    dimension 2, not 256"; a Normalize as its repr (review28)."""
    cases = [(matplotlib.colors.Normalize(), "matplotlib.colors.Normalize")]
    if hasattr(matplotlib, "bivar_colormaps"):  # matplotlib 3.10 on
        cases += [(matplotlib.bivar_colormaps["BiPeak"], "matplotlib.colors.SegmentedBivarColormap"),
                  (matplotlib.multivar_colormaps["2VarAddA"], "matplotlib.colors.MultivarColormap")]
    for given, name in cases:
        with pytest.raises(clwave.InputError) as err:
            clwave.TransferFunction.from_colormap(given)
        assert str(err.value) == f"from_colormap takes a matplotlib Colormap (of one variable) or its name, got {name}"
