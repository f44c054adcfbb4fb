"""The outputs of ``tools/compare_peers.py`` (docs/peers.md): the table, the headline ratios, the error-against-time
plot and the montage of first views, from its report."""

from __future__ import annotations

import statistics

import numpy as np

TARGET_ERROR = 0.01  #: the error every method is timed to (relative RMS)


def target_text(seconds, best_error) -> str:
    return f"{seconds:.3g} s" if seconds is not None else f"not reached (best {100 * best_error:.3g} %)"


def have(package) -> bool:
    import importlib.util
    return importlib.util.find_spec(package) is not None


def row_text(row) -> str:
    if "skipped" in row:
        return f"{row['method']}: skipped ({row['skipped']})"
    err = f"error {row['error']:.2e}" if "error" in row else "error n/a"
    m = row["memory_mib"]
    return f"{row['method']}: first {row['first']:.3f} s, median {row['median']:.4f} s, {err}, " \
           f"peak {row['peak_rss_mib']:.0f} MiB (baseline {m['baseline']:.0f} + model {m['model']:.0f} " \
           f"+ views {m['views']:.0f})"


# ----------------------------------------------------------------------------- outputs
def markdown(report) -> str:
    lines = ["| phantom | size | method | prepare s | first view s | median view s | peak RSS MiB "
             "(baseline + model + views) | rel. RMS error | time to 1 % |", "|---|---|---|---|---|---|---|---|---|"]
    for case in report["cases"]:
        for row in case["rows"]:
            head = f"| {case['phantom']} | {case['n']}³ | {row['method']} "
            if "skipped" in row:
                lines.append(head + f"| skipped: {row['skipped']} | | | | | |")
                continue
            prep = "" if row.get("prepare") is None else f"{row['prepare']:.2f}"
            m = row["memory_mib"]
            error = f"{100 * row['error']:.3g} %" if "error" in row else "n/a"
            error += " (shaded)" if "error" in row and row["kind"] == "shaded" else ""
            target = row["target_text"] if "error" in row else ("the reference" if row["kind"] == "shaded"
                                                                  else "speed reference only")
            lines.append(head + f"| {prep} | {row['first']:.3g} | {row['median']:.3g} | {row['peak_rss_mib']:.0f} "
                         f"({m['baseline']:.0f} + {m['model']:.0f} + {m['views']:.0f}) | {error} | {target} |")
    return "\n".join(lines) + "\n"


def headline(report) -> list:
    """clwave / FVR and clwave / VTK per case: X-ray (splat, reused and one-shot) and shaded (ray tracing)."""
    out = []
    for case in report["cases"]:
        rows = [r for r in case["rows"] if "skipped" not in r]
        find = lambda start: next((r for r in rows if r["method"].startswith(start)), None)  # noqa: E731
        reused = min((r for r in rows if r["method"].endswith("renderer reused") and r.get("to_target")),
                     key=lambda r: r["to_target"], default=None)
        oneshot, fvr, vtk = find("clwave splat") and next(
            (r for r in rows if "one-shot" in r["method"]), None), find("Fourier"), find("VTK additive")
        where = f"{case['phantom']} {case['n']}³ at {report['image']}²"
        for r in (reused, oneshot):
            if r is None:
                continue
            text = f"{where}: {r['method']} {1e3 * r['median']:.1f} ms (error {100 * r['error']:.3g} %, " \
                   f"peak {r['peak_rss_mib']:.0f} MiB)"
            if fvr:
                text += f"; FVR {1e3 * fvr['median']:.1f} ms ({100 * fvr['error']:.3g} %, peak " \
                        f"{fvr['peak_rss_mib']:.0f} MiB, spectrum {fvr['extra']['spectrum_mib']:.0f} MiB): " \
                        f"clwave / FVR = {r['median'] / fvr['median']:.2f}"
            if vtk:
                text += f"; VTK additive Render() {1e3 * vtk['median']:.1f} ms: " \
                        f"clwave / VTK = {r['median'] / vtk['median']:.2f}"
            out.append(text)
        composite = find("VTK composite")
        for r in (r for r in rows if r["kind"] == "shaded" and r["method"].startswith("clwave")):
            text = f"{where}, shaded: {r['method']} {r['median']:.3g} s (error {100 * r['error']:.3g} %)"
            if composite and "error" in composite:
                text += f"; VTK composite Render() {composite['median']:.3g} s (error " \
                        f"{100 * composite['error']:.3g} %): clwave / VTK = {r['median'] / composite['median']:.1f}"
            out.append(text)
        out += [equal_error_text(case, report["image"], found) for found in equal_error(rows)]
        if "eight_bit_error" in case:
            out.append(f"{where}: VTK's 8-bit output alone (the float64 reference over [0, window] rounded to 8 bits) "
                       "is " + ", ".join(f"{100 * e:.3g} % at window {w}" for w, e in case["eight_bit_error"].items()))
    return out


def plot(report, path) -> bool:
    """Error against time per case: X-ray methods (top) and shaded ones (bottom, where measured)."""
    if not have("matplotlib"):
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.ticker import NullFormatter

    cases = report["cases"]
    shaded = any(r.get("kind") == "shaded" and "error" in r for c in cases for r in c["rows"])
    xray = any(r.get("kind") == "xray" for c in cases for r in c["rows"])  # none with --skip-xray
    fig, axes = plt.subplots(xray + shaded, len(cases), figsize=(5.6 * len(cases), 4.4 * (xray + shaded)),
                             squeeze=False)
    for col, case in enumerate(cases):
        rows = [r for r in case["rows"] if "skipped" not in r]
        if xray:
            ax = axes[0, col]
            prog = [r for r in rows if r["method"].startswith("clwave progressive")]
            if prog:
                ax.plot([r["median"] for r in prog], [r["error"] for r in prog], "o-", color="C0",
                        label="clwave progressive")
                for r in prog:
                    ax.annotate(f"{100 * r['kept']:.3g}%", (r["median"], r["error"]), fontsize=7,
                                textcoords="offset points", xytext=(4, 4))
            for r, style in zip([r for r in rows if r["method"].startswith("clwave splat")], ("s", "p", "h", "8")):
                ax.plot([r["median"]], [r["error"]], style, color="C1", markersize=8, label=r["method"])
            for r in [r for r in rows if r["method"].startswith("clwave raytrace") and r["kind"] == "xray"]:
                ax.plot([r["median"]], [r["error"]], "*", color="C5", markersize=11, label=r["method"])
            for r, style, colour in zip([r for r in rows if r["method"] in ("NumPy/SciPy map_coordinates",
                                                                           "Fourier volume rendering")], ("^", "D"),
                                        ("C4", "C2")):
                ax.plot([r["median"]], [r["error"]], style, color=colour, markersize=8, label=r["method"])
            for r in [r for r in rows if r["method"] == "VTK additive"]:
                ax.axvline(r["median"], color="C3", ls=":", label="VTK additive Render() (time only)")
            _axes(ax, f"{case['phantom']} {case['n']}³, {report['image']}², X-ray", "relative RMS error vs analytic",
                  NullFormatter)
        if shaded:
            ax = axes[int(xray), col]
            for r, style in zip([r for r in rows if r["kind"] == "shaded" and "error" in r and "sweep" not in r],
                                ("*", "P", "X", "o")):
                ax.plot([r["median"]], [r["error"]], style, markersize=10, label=r["method"])
            series = {}
            for r in (r for r in rows if "sweep" in r):
                series.setdefault((r["sweep"]["side"],) + _setting(r)[1:], []).append(r)
            for name, runs in series.items():
                runs.sort(key=lambda r: _setting(r)[0])
                ax.plot([r["median"] for r in runs], [r["error"] for r in runs], ".-" if name[0] == "vtk" else "s--",
                        label="sweep: VTK {} x{} window {:.3g}, over its distance".format(*name[1:]) if name[0] == "vtk"
                        else "sweep: clwave over its tolerance")
            _axes(ax, f"{case['phantom']} {case['n']}³, shaded", "relative RMS error vs float64 ray trace",
                  NullFormatter)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _axes(ax, title, ylabel, null):
    ax.axhline(TARGET_ERROR, color="grey", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(null())
    ax.yaxis.set_minor_formatter(null())
    ax.set_xlabel("seconds per view (median)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


def montage(images, title, path) -> bool:
    """First-view images of every method side by side (each windowed to its own range)."""
    if not have("matplotlib"):
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(images), figsize=(2.3 * len(images), 2.7))
    for ax, (label, image) in zip(np.atleast_1d(axes), images.items()):
        ax.imshow(image, cmap="gray", vmin=0.0, vmax=float(np.percentile(image, 99.9)) or 1.0)
        ax.set_title(label, fontsize=7)
        ax.axis("off")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


# ----------------------------------------------------------------------------- at equal error
def sweep_rows(res, references, error_of) -> list:
    """One row per clwave tolerance and VTK setting of compare_peers' ``run_sweep``, its error ``error_of`` (image,
    reference) the median over the views against the post-classified float64 references, its time the median over
    all its renders (views and rounds)."""
    rows = []
    for job in res["jobs"]:
        if job["side"] == "clwave":
            setting = dict(side="clwave", tolerance=job["setting"])
            label = f"sweep: clwave raytrace {res['keep']:g} (post-classified, tol {job['setting']:g})"
        else:
            setting = dict(zip(("side", "distance", "interpolation", "resample", "window"), ("vtk", *job["setting"])))
            label = "sweep: VTK composite, distance {distance:g}, {interpolation}, volume x{resample}, " \
                    "window {window:.3g}".format(**setting)
        error = statistics.median(error_of(im, ref) for im, ref in zip(job["images"], references))
        rows.append(dict(method=label, kind="shaded", sweep=setting, prepare=job["prepare"], first=job["seconds"][0],
                         median=statistics.median(job["seconds"]), error=error, peak_rss_mib=res["peak_rss_mib"],
                         memory_mib=res["memory_mib"], to_target=None, target_text="",
                         extra=dict(seconds=job["seconds"], rounds=res["rounds"])))
    return rows


def equal_error(rows) -> list:
    """Time at equal error from a case's sweep rows (compare_peers ``--vtk-sweep``), both ways: for each clwave
    tolerance, VTK's time at clwave's error; for VTK at its defaults and at its lowest error, clwave's time at
    VTK's error. Each is ``at_error`` of the other side's rows: one dict per comparison."""
    sweep = [r for r in rows if "sweep" in r]
    sides = {side: [r for r in sweep if r["sweep"]["side"] == side] for side in ("clwave", "vtk")}
    if not sides["clwave"] or not sides["vtk"]:
        return []
    out = [dict(given=r, **at_error(sides["vtk"], r["error"])) for r in sides["clwave"]]
    default = next((r for r in sides["vtk"] if _setting(r)[1:] == ("linear", 1, 1.0) and r["sweep"]["distance"] == 1),
                   None)
    best = min(sides["vtk"], key=lambda r: r["error"])
    out += [dict(given=r, **at_error(sides["clwave"], r["error"])) for r in (default, best) if r is not None]
    return out


def at_error(rows, error) -> dict:
    """The fastest of ``rows`` (one side of a sweep) whose error is at most ``error`` ("measured"), or, where faster,
    the time at which a series (one VTK volume, interpolation and window over its sample distances; clwave over its
    tolerances) crosses ``error`` between two neighbouring settings, interpolated in log time against log error
    ("interpolated"); ``seconds`` None (with the side's lowest error, its floor) where no setting reaches it."""
    found = dict(seconds=None, how="not reached", row=min(rows, key=lambda r: r["error"]))
    reached = [r for r in rows if r["error"] <= error]
    if reached:
        found = dict(seconds=min(r["median"] for r in reached), how="measured",
                     row=min(reached, key=lambda r: r["median"]))
    series = {}
    for r in rows:
        series.setdefault(_setting(r)[1:], []).append(r)
    for runs in series.values():
        runs.sort(key=lambda r: _setting(r)[0])
        for a, b in zip(runs, runs[1:]):
            if (a["error"] - error) * (b["error"] - error) < 0:
                w = np.log(error / a["error"]) / np.log(b["error"] / a["error"])
                seconds = float(np.exp((1 - w) * np.log(a["median"]) + w * np.log(b["median"])))
                if found["seconds"] is None or seconds < found["seconds"]:
                    found = dict(seconds=seconds, how="interpolated", row=a, between=b)
    return found


def _setting(row) -> tuple:
    """The swept value first (VTK's sample distance, clwave's tolerance), then what names the series."""
    s = row["sweep"]
    if s["side"] == "clwave":
        return (s["tolerance"],)
    return s["distance"], s["interpolation"], s["resample"], s["window"]


def equal_error_text(case, image, found) -> str:
    given, row = found["given"], found["row"]
    other = "VTK" if given["sweep"]["side"] == "clwave" else "clwave"
    head = f"{case['phantom']} {case['n']}³ at {image}², at equal error: {_short(given)} {given['median']:.3g} s at " \
           f"{100 * given['error']:.3g} %; {other} "
    if found["seconds"] is None:
        return head + f"does not reach it (its lowest error {100 * row['error']:.3g} %, {_short(row)})"
    where = _short(row) if found["how"] == "measured" else f"between {_short(row)} and {_short(found['between'])}"
    clwave, vtk = (given["median"], found["seconds"]) if other == "VTK" else (found["seconds"], given["median"])
    return head + f"{found['seconds']:.3g} s ({found['how']}: {where}): clwave / VTK = {clwave / vtk:.2f}"


def _short(row) -> str:
    s = row["sweep"]
    if s["side"] == "clwave":
        return f"clwave tol {s['tolerance']:g}"
    return f"VTK distance {s['distance']:g} {s['interpolation']} x{s['resample']} window {s['window']:.3g}"
