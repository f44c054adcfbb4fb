"""A progressive viewer in the browser (docs/viewer.md): ``clwave.view(...)`` and ``clwave view INPUT``."""

from __future__ import annotations

from os import PathLike

from ..errors import InputError, type_name, warn_outside
from ..model.tf_file import as_transfer_function
from ..model.wavelet import DEFAULT_KEEP, WaveletVolume


class Viewer:
    """A running viewer: open :attr:`url` in a browser (it holds the token); in a Jupyter notebook the object
    shows the page inline.  :meth:`close` stops the server, :meth:`close_all` every viewer still open (a notebook's
    cell run again makes a new one beside the old, docs/viewer.md §1); a viewer still open is closed at the
    interpreter's exit (:mod:`clwave.view.main_end`), so that the exit does not wait for the render under way."""

    def __init__(self, background):
        from .main_end import close_at_exit

        self._background = background
        self.server = background.server
        close_at_exit(background)

    @property
    def url(self) -> str:
        return self.server.url

    def close(self):
        from .main_end import closed

        self._background.close()
        closed(self._background)

    @staticmethod
    def close_all() -> int:
        """Close every viewer still open (as napari's ``Viewer.close_all``): their ports freed and their threads
        ended; returns how many were open."""
        from .main_end import close_all

        return close_all()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return f"<clwave viewer at {self.url}>"

    def _repr_html_(self):
        import html

        h, w = self.server.sources["xray"].size
        return (f'<iframe src="{html.escape(self.url)}" width="{w + 300}" height="{max(h, 400) + 60}" '
                f'style="border: 0"></iframe>')


def as_model(model_or_volume, keep=DEFAULT_KEEP, tf=None, wavelet="cubic", levels=None, classify="pre"):
    """A thresholded :class:`~clwave.WaveletVolume` from a model (as it is), a :class:`~clwave.Volume` or an
    array ``(z, y, x[, c])`` (NumPy, Dask or an xarray DataArray, as :class:`~clwave.Volume` takes it): classified
    with ``tf`` (as :func:`~clwave.model.tf_file.as_transfer_function` takes it) first, or with
    ``classify="post"`` the scalar kept with ``tf`` as its transfer function, classified while rendering
    (docs/raytracing.md §10)."""
    from ..model.volume import Volume, is_dask

    if isinstance(model_or_volume, WaveletVolume):
        return model_or_volume
    if isinstance(model_or_volume, (str, PathLike)):  # a path other than a .clw file's: a volume file
        raise InputError(f"view() reads a .clw file by its path; read a volume file first (its options, e.g. "
                         f"spacing= or hu_to_mu=, are load's): clwave.view(clwave.load({str(model_or_volume)!r}))")
    if hasattr(model_or_volume, "__array__") or is_dask(model_or_volume):  # NumPy, Dask, a DataArray
        model_or_volume = Volume(model_or_volume)
    if not isinstance(model_or_volume, Volume):
        raise InputError(f"view() takes a clwave.WaveletVolume, a clwave.Volume, an array (NumPy, Dask or an xarray "
                         f"DataArray) or a .clw file, got {type_name(model_or_volume)}")
    _check_classify(classify)
    vol, tf = model_or_volume, as_transfer_function(tf, "tf")
    if tf is not None:
        if classify == "post" and vol.channels != 1:
            raise InputError(f'classify="post" keeps a scalar volume for ray tracing to classify; this volume has '
                             f'{vol.channels} channels: leave classify out')
        tf = tf.resolved(vol)
        vol = tf.classify(vol) if classify == "pre" else vol
    wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=levels, transfer_function=tf)
    if not vol.chunked:  # recorded in the model: the frame of a noisy volume's content (camera.framed_box)
        wv.measure_noise()
    wv = wv.threshold(keep=keep)
    return wv.compute() if vol.chunked else wv  # a chunked volume's model, gathered


def _check_classify(classify):
    if classify not in ("pre", "post"):
        raise InputError(f"classify={classify!r} must be 'pre' (classify a volume before its transform) or 'post' "
                         f"(while rendering)")


def view(model_or_volume, *, size=512, tolerance=1e-2, keep=None, tf=None, classify="pre", device=None,
         device_memory=None, host="127.0.0.1", port=0, open_browser=False) -> Viewer:
    """Serve a progressive view of a model, a volume (a :class:`~clwave.Volume`, or an array as it takes one: NumPy,
    Dask, an xarray DataArray) or a ``.clw`` file in the browser; returns a :class:`Viewer`.

    ``size`` (N or (H, W)) is the full image; ``tolerance`` the shaded mode's when the view is still (an RGBA
    model, or a scalar one classified at render time through the page's transfer-function editor).  ``tf`` (a preset
    name, a ``.json`` or ``.csv`` file of points, docs/model.md §5, a matplotlib colormap or a TransferFunction): a
    volume is classified with it before its transform (``classify="pre"``), or kept scalar and classified with it
    while rendering (``classify="post"``); a scalar model or ``.clw`` file is classified with it while rendering; the
    editor starts from it (else from the model's own, or grey).  A volume is decomposed with cubic wavelets and
    ``keep`` (default 0.05) of its voxels kept; a ``.clw`` file (a path) is served
    at once from its most important coefficients while the rest (its ``keep`` most important, default all) is read
    (docs/viewer.md §2).  ``device_memory`` (bytes or a size such as "2GiB"; default the device's) caps the device
    memory of the viewer's renderers together (docs/viewer.md §1).  The server binds ``host`` (loopback unless
    given) at ``port`` (0: a free one); every request needs the token in :attr:`Viewer.url`.  ``open_browser`` opens
    it.
    """
    from ..device.memory import parse_cap
    from ..model.camera import Camera
    from .frames import check_tolerance
    from .export import Origin
    from .prefix import PrefixFirst
    from .address import check_host, check_port, is_loopback
    from .background import BackgroundServer
    from .server import ViewServer

    size = Camera(size=size).size
    check_host(host)
    check_port(port)
    check_tolerance(tolerance)
    _check_classify(classify)
    parse_cap(device_memory)
    tf = as_transfer_function(tf, "tf")
    if isinstance(model_or_volume, (str, PathLike)) and str(model_or_volume).lower().endswith(".clw"):
        wv = PrefixFirst(model_or_volume, keep=keep)
        model = wv.prefix
    else:
        model = model_or_volume if isinstance(model_or_volume, WaveletVolume) else None  # else a volume's tf is its own
        wv = as_model(model_or_volume, keep=DEFAULT_KEEP if keep is None else keep, tf=tf, classify=classify)
    if model is not None and tf is not None and model.channels != 1:  # a model: classified while rendering
        raise InputError(f"tf= classifies a scalar model while rendering; this model has {model.channels} channels "
                         f"(classified already): leave tf out")
    if not is_loopback(host):
        warn_outside(f"the viewer listens on {host}: anyone who can reach it and learns the address with its token "
                     f"can see this volume")
    # a .clw file's path: a view's command line reads it (export.py); a model or volume given here, none does
    origin = Origin(str(model_or_volume), () if keep is None else (("keep", "--keep", keep),)) \
        if isinstance(wv, PrefixFirst) else None
    server = ViewServer(wv, size, tolerance=tolerance, device=device, host=host, port=port,
                        transfer_function=None if model is None else tf, device_memory=device_memory, origin=origin)
    viewer = Viewer(BackgroundServer(server))
    if open_browser:
        import webbrowser
        webbrowser.open(viewer.url)
    return viewer
