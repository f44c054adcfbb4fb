"""``clwave view``: a progressive viewer in the browser (docs/viewer.md)."""

from __future__ import annotations

import sys

from .checks import check_image_size, parse_size
from .options import add_model_options, build_model, parse_device_memory, post_transfer_function, warn
from .reading import add_input_options


#: host memory the viewer holds a pixel of its --size on a CPU device at the least (its X-ray and shaded images, their
#: device buffers, read-backs and encoding), a floor of its measured peak (docs/viewer.md §1)
VIEW_PIXEL_BYTES = 200


def run(args):
    import asyncio
    import logging

    from ..view.export import Origin
    from ..view.prefix import PrefixFirst
    from ..view.address import check_host, check_port, is_loopback
    from ..view.server import ViewServer

    size = tuple(parse_size(args))
    check_size(size, args.device)
    device_memory = parse_device_memory(args)
    check_host(args.host)
    check_port(args.port)
    # a .clw file: its prefix now, the rest read while serving; a scalar model's shaded views are classified while
    # rendering by --tf [--tf-window] (a .clw input; a volume's with --classify post), checked as `render` checks them
    wv, _ = build_model(args, opener=PrefixFirst, post=True, noise=True)
    tf = post_transfer_function(args, wv.prefix if isinstance(wv, PrefixFirst) else wv)
    if isinstance(wv, PrefixFirst) and not wv.complete:
        print(f"clwave view: serving the {wv.prefix.kept:,} most important coefficients of {args.input} at once; "
              f"the rest is read while serving", file=sys.stderr, flush=True)
    handler = logging.StreamHandler(sys.stderr)  # the server's refusals and closings; not other libraries' logs
    handler.setFormatter(logging.Formatter("clwave view: %(message)s"))
    logging.getLogger("clwave.view").addHandler(handler)
    logging.getLogger("clwave.view").setLevel(logging.INFO)
    server = ViewServer(wv, size, tolerance=args.tolerance, device=args.device, host=args.host, port=args.port,
                        transfer_function=tf, device_memory=device_memory, origin=Origin.of_args(args))

    async def serve():
        url = await server.start()  # or an InputError: the port in use
        if not is_loopback(args.host):
            warn(f"listening on {args.host}, not only on this machine: anyone who can reach it and learns the "
                 f"address with its token can see this volume")
        print(f"clwave view: open {url}", flush=True)
        print("clwave view: Ctrl-C stops the server", file=sys.stderr, flush=True)
        if args.open:
            import webbrowser
            if not webbrowser.open(url):
                print("clwave view: no browser found here; open the address above", file=sys.stderr)
        try:
            await asyncio.Event().wait()  # until interrupted
        finally:
            await server.stop()

    try:
        asyncio.run(serve())
    except KeyboardInterrupt:
        print("clwave view: stopped", file=sys.stderr)
    return 0


def check_size(size, device):
    """Refuse, before the input is read, an image size the viewer could not hold: its ray tracer's traced image in
    one device buffer (:func:`~.checks.check_image_size`, the other commands' check), the viewer's largest (the X-ray
    framebuffer takes less), and on a CPU device (its memory the host's) its images' memory, :data:`VIEW_PIXEL_BYTES`
    a pixel, beyond what the host has available (docs/viewer.md §1): a server holds more a pixel than its one buffer
    (both views' images, their read-backs and encodings), so this second check is the viewer's own.
    The shaded views are served for a scalar or an RGBA model; the channels are known once the input is read, so
    every model is held to their limit."""
    from math import isqrt

    from ..device.context import ComputeContext
    from ..device.memory import TRACED_PIXEL_BYTES, available_bytes, check_fits

    if ComputeContext.get(device).info.kind == "CPU":  # first: more a pixel than the one buffer's check holds
        (H, W), fits = size, isqrt(available_bytes() // VIEW_PIXEL_BYTES)  # (a device of its own: not measured)
        check_fits(H * W * VIEW_PIXEL_BYTES, f"a viewer of {H}x{W} images",
                   f"give a smaller --size (at most {fits}x{fits} here now)")
    check_image_size(size, device, TRACED_PIXEL_BYTES, "the viewer's {} shaded image")


def add_parser(sub):
    p = sub.add_parser("view", help="a progressive viewer in the browser (X-ray and shaded)")
    add_input_options(p)
    add_model_options(p)
    g = p.add_argument_group("viewer")
    g.add_argument("--size", default="512", help="image size: N or HxW (default 512)")
    g.add_argument("--tolerance", type=float, default=1e-2, help="shaded: error per value when still (default 1e-2)")
    g.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    g.add_argument("--device-memory", metavar="SIZE", help="device memory the viewer's renderers use at most "
                                                           "together, e.g. 2GiB (default: the device's)")
    g.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1, this machine "
                                                        "only; another one is reachable by others: a warning)")
    g.add_argument("--port", type=int, default=0, help="port (default: a free one)")
    g.add_argument("--open", action="store_true", help="open the address in a browser, where one exists")
    p.set_defaults(run=run)
    return p
