"""``clwave info``: the OpenCL platforms and devices, and the one chosen."""

from __future__ import annotations

import json


def run(args):
    from ..device.context import list_devices, requested_device, select_device
    from ..device.programs import selftest

    devices = list_devices()
    chosen = select_device(args.device, devices)
    if args.json:
        print(json.dumps(dict(devices=[d.describe() for d in devices], auto=chosen.id,
                              request=requested_device(args.device)), indent=2))
    else:
        mib = 1024 ** 2
        platform = None
        for d in devices:
            if d.platform != platform:
                platform = d.platform
                print(f"platform {d.platform_index}: {d.platform}")
            mark = "  <- chosen" if d == chosen else ""
            print(f"  {d.id}  {d.name} [{d.kind}]{mark}\n"
                  f"        global memory {d.global_mem / mib:,.0f} MiB, max allocation "
                  f"{d.max_alloc / mib:,.0f} MiB, local memory {d.local_mem / 1024:,.0f} KiB, "
                  f"{d.compute_units} compute units, {d.version}")
        print(f"device request {requested_device(args.device)!r} -> {chosen.id} {chosen.name}")
    if args.check:
        from ..device.context import ComputeContext
        seconds = selftest(ComputeContext.get(chosen.id))
        print(f"self-test kernel built in {seconds:.2f} s and ran correctly on {chosen.name}")
    return 0


def add_parser(sub):
    p = sub.add_parser("info", help="list OpenCL platforms and devices, and the one chosen")
    p.add_argument("--device", default=None, help="auto, cpu, gpu, P:D or a name substring")
    p.add_argument("--check", action="store_true", help="also build and run a self-test kernel")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=run)
