"""The report of a campaign's results: pass rates, maps, histograms and the worst cases.

``build(out)`` reads ``out``'s chunk files and writes into ``out/report/``:

* ``pass_map_<calibration>.png``: the pass rate over mu x v (10 x 10 bins), per calibration;
* ``hist_<metric>.png``: each judged figure's histogram over the runs that did not spin (a spun
  run's figures stop at its spin; the legend names their share), the calibrations overlaid, the
  criterion's bound drawn; a sensor fault's figures over the samples with one (none: no
  histogram);
* ``index.html``: pass rates per criterion and calibration, per disturbance kind, why runs
  failed (the spun runs, then per criterion the runs that did not spin and failed it, and those
  that failed it alone), the figures, and the ``WORST`` worst samples of each calibration by peak
  yaw rate with all their parameters (``mrsteer campaign export DIR INDEX`` replays one; a
  sensor fault's parameters and figures only for a sample with one).

It returns the summary numbers (also what ``campaign report --json`` prints).
"""

from __future__ import annotations

import html
import json
import math
import io
from pathlib import Path
from typing import Any

import numpy as np

from firmware_py.platform.files import write_files
from sim_plant.campaign import results
from sim_plant.campaign.engine import METRICS
from sim_plant.campaign.params import INDEX, KINDS, PARAMETERS
from sim_plant.campaign.runner import SPEC_FILE
from sim_plant.campaign.spec import CRITERIA, FAULT_PARAMETERS, SpecError, parse
from sim_plant.car.nonlinear import SPIN_SIDE_SLIP

WORST = 10
BINS = 10
#: a sensor fault's parameters and figures: none for a sample without one
FAULT_COLUMNS = ("fault_sensor", *FAULT_PARAMETERS, "detection_time", "fault_yaw_rate", "twin_yaw_rate")


def read(out: Path) -> tuple[Any, dict[str, np.ndarray]]:
    """The campaign file and the results of the directory ``out``, or one line of why not."""
    spec = out / SPEC_FILE
    if not spec.is_file():
        raise SpecError(f"{out}: not a campaign's results directory (no {SPEC_FILE}; "
                        "`mrsteer campaign run FILE --out DIR` makes one)")
    c = parse(spec.read_text(), str(spec))
    cols = {k: np.asarray(v) for k, v in results.read_all(out).to_pydict().items()}
    if "spun" not in cols:
        raise SpecError(f"{out}: results written before runs ended at a spin: run the campaign again into a new --out")
    return c, cols


def summarise(out: Path) -> dict[str, Any]:
    """Pass rates (overall, per criterion, per disturbance kind), why runs failed and the worst
    cases, per calibration."""
    c, cols = read(out)
    faults = bool(np.any(cols["fault_sensor"] != "none"))
    summary: dict[str, Any] = {"campaign": c.name, "samples": c.samples, "criteria": c.criteria, "calibrations": {}}
    for name in c.calibrations:
        m = cols["calibration"] == name
        rows = {k: v[m] for k, v in cols.items()}
        n, spun = int(m.sum()), rows["spun"]
        kept = ~spun
        per_kind = {k: float(np.mean(rows["pass"][rows["disturbance"] == k])) for k in KINDS
                    if np.any(rows["disturbance"] == k)}
        spun_kind = {k: int(np.count_nonzero(spun[rows["disturbance"] == k])) for k in KINDS
                     if np.any(rows["disturbance"] == k)}
        failed = {k: ~rows[f"pass_{k}"] & kept for k in c.criteria}
        how_many = np.sum(list(failed.values()), axis=0) if failed else np.zeros(n)
        order = np.argsort(-rows["peak_yaw_rate"])[:WORST]
        summary["calibrations"][name] = {
            "runs": n, "passed": int(np.count_nonzero(rows["pass"])),
            "pass_rate": float(np.mean(rows["pass"])) if n else None,
            "spun": int(np.count_nonzero(spun)), "spun_share": float(np.mean(spun)) if n else None,
            # per criterion over the runs that did not spin (a spun run's figures stop at the spin)
            "per_criterion": {k: float(np.mean(rows[f"pass_{k}"][kept])) if kept.any() else None
                              for k in c.criteria},
            "failed": {k: {"runs": int(np.count_nonzero(f)), "alone": int(np.count_nonzero(f & (how_many == 1)))}
                       for k, f in failed.items()},
            "per_disturbance": per_kind, "spun_per_disturbance": spun_kind,
            "worst": [_worst_row(rows, i, faults) for i in order],
            "figures": {k: _figures(rows[k][kept]) for k in CRITERIA if _figures(rows[k][kept])},
        }
    return summary


def _worst_row(rows: dict[str, np.ndarray], i: int, faults: bool) -> dict[str, Any]:
    """Row i's parameters and figures: a sensor fault's only in a campaign with faults, and
    None for a sample without one; a spin's time None for a run that did not spin."""
    keys = [k for k in (INDEX, *PARAMETERS, *METRICS) if faults or k not in FAULT_COLUMNS]
    row = {k: _plain(rows[k][i]) for k in keys}
    if rows["fault_sensor"][i] == "none":
        row.update({k: None for k in FAULT_COLUMNS if k in row and k != "fault_sensor"})
    if not row["spun"]:
        row["spin_time"] = None
    return row


def _figures(values: np.ndarray) -> dict[str, float]:
    """Median, 99th percentile and largest of a figure (NaN, a sensor fault's without one, left
    out); {} without any."""
    values = values[~np.isnan(values)]
    if not values.size:
        return {}
    return {"median": float(np.median(values)), "p99": float(np.percentile(values, 99)), "max": float(np.max(values))}


def as_json(summary: Any) -> str:
    """``summary`` as strict JSON (what ``campaign report --json`` prints): a non-finite figure, such
    as the ``detection_time`` of a fault never reported (inf), is null."""
    def finite(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: finite(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [finite(v) for v in x]
        return x
    return json.dumps(finite(summary), indent=2, allow_nan=False)


def _plain(x: Any) -> Any:
    return x.item() if hasattr(x, "item") else x


def build(out: Path) -> dict[str, Any]:
    """The figures and index.html in ``out/report``; the summary."""
    summary = summarise(out)  # a directory that is no campaign's is refused before plotting loads
    _, cols = read(out)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = out / "report"
    files: dict[str, bytes | str] = {}
    for name in summary["calibrations"]:
        m = cols["calibration"] == name
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
        mu, v, ok = cols["mu"][m], cols["v"][m], cols["pass"][m].astype(float)
        tot, xe, ye = np.histogram2d(mu, v, bins=BINS)
        good, _, _ = np.histogram2d(mu, v, bins=[xe, ye], weights=ok)
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = good / tot
        im = ax.pcolormesh(ye, xe, rate, vmin=0.0, vmax=1.0, cmap="RdYlGn")
        fig.colorbar(im, ax=ax, label="pass rate")
        ax.set(xlabel="v at the start (m/s)", ylabel="road mu", title=f"{name}: pass rate over mu x v")
        files[f"pass_map_{_safe(name)}.png"] = _png(fig)
    for metric in CRITERIA:
        shown = ~cols["spun"] & ~np.isnan(cols[metric])  # (NaN: a sensor fault's figure without one)
        if not shown.any():
            continue
        fig, ax = plt.subplots(figsize=(5.5, 4.0))
        every = cols[metric][shown]
        # one set of bins for every calibration; (a detection_time of inf, never reported, has
        # no bin: the summary's max shows it)
        edges = np.histogram_bin_edges(every[np.isfinite(every)], bins=50)
        for name, c in summary["calibrations"].items():
            values = cols[metric][shown & (cols["calibration"] == name)]
            spun = f", {c['spun']} spun ({c['spun_share']:.1%}) not shown" if c["spun"] else ""
            ax.hist(values[np.isfinite(values)], bins=edges, alpha=0.5, label=f"{name}: {values.size} runs{spun}")
        bound = summary["criteria"].get(metric)
        if bound is not None:
            ax.axvline(bound, color="k", ls="--", label="criterion")
        unit = METRICS[metric][0]
        ax.set(xlabel=f"{metric} ({unit})" if unit else metric, ylabel="runs", yscale="log",
               title="runs that did not spin" + (" and had a sensor fault" if metric in FAULT_COLUMNS else ""))
        ax.legend(fontsize="small")
        files[f"hist_{metric}.png"] = _png(fig)
    plt.close("all")
    files["index.html"] = _html(summary, list(files))
    rep.mkdir(parents=True, exist_ok=True)
    summary["files"] = [str(p) for p in write_files(rep, files)]  # all of them or none
    return summary


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in Path(name).stem)


def _png(fig) -> bytes:
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


def _html(s: dict[str, Any], images: list[str]) -> str:
    e = html.escape
    crit = ", ".join(f"{k} &le; {v:g}" for k, v in s["criteria"].items()) or "none"
    parts = [f"<!doctype html><meta charset='utf-8'><title>campaign {e(s['campaign'])}</title>",
             "<style>body{font-family:sans-serif;max-width:75em;margin:auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}</style>",
             f"<h1>Campaign {e(s['campaign'])}</h1><p>{s['samples']} samples per calibration; criteria: {crit}. "
             "A run passes when its figures are within every criterion and its car did not spin (its side slip "
             f"beyond {math.degrees(SPIN_SIDE_SLIP):g}&deg;, where the car model ends: the run ends there, and its figures are those up to the "
             "spin).</p>",
             "<h2>Pass rates</h2><p>All runs; per criterion, the runs that did not spin; per disturbance, all runs "
             "of that kind (the spun ones in brackets).</p>"
             "<table><tr><th>calibration</th><th>runs</th><th>all</th><th>spun</th>"
             + "".join(f"<th>{e(k)}</th>" for k in s["criteria"]) + "".join(f"<th>{k}</th>" for k in KINDS) + "</tr>"]
    for name, c in s["calibrations"].items():
        parts.append(f"<tr><td>{e(name)}</td><td>{c['runs']}</td><td>{_rate(c['pass_rate'])}</td>"
                     f"<td>{c['spun']} ({_rate(c['spun_share'], '.1%')})</td>"
                     + "".join(f"<td>{_rate(c['per_criterion'][k])}</td>" for k in s["criteria"])
                     + "".join(f"<td>{_rate(c['per_disturbance'].get(k))} ({c['spun_per_disturbance'].get(k, 0)})"
                               "</td>" for k in KINDS) + "</tr>")
    parts.append("</table>")
    parts.append(_failures(s))
    parts += [f"<p><img src='{e(i)}'></p>" for i in images]
    for name, c in s["calibrations"].items():
        keys = list(c["worst"][0]) if c["worst"] else []
        parts.append(f"<h2>Worst {len(c['worst'])} by peak yaw rate: {e(name)}</h2>"
                     "<p>Replay one: <code>mrsteer campaign export DIR INDEX --out FILE.toml</code>, then "
                     "<code>mrsteer hil run --scenario FILE.toml</code>.</p><table><tr>"
                     + "".join(f"<th>{e(k)}</th>" for k in keys) + "</tr>")
        for w in c["worst"]:
            parts.append("<tr>" + "".join(f"<td>{_cell(w[k])}</td>" for k in keys) + "</tr>")
        parts.append("</table>")
    return "\n".join(parts) + "\n"


def _failures(s: dict[str, Any]) -> str:
    """Why runs did not pass, per calibration: the spun runs, then per criterion how many of the
    runs that did not spin failed it, and how many failed it alone (so that the spun runs, the
    runs that failed one criterion alone and those that failed several add up to the failures)."""
    e = html.escape
    cals = s["calibrations"]
    head = "".join(f"<th>{e(name)}</th>" for name in cals)
    lines = [f"<tr><td>passed</td>" + "".join(f"<td>{c['passed']} of {c['runs']}</td>" for c in cals.values()) + "</tr>",
             "<tr><td>spun (their figures stop at the spin: not judged)</td>"
             + "".join(f"<td>{c['spun']}</td>" for c in cals.values()) + "</tr>"]
    for k in s["criteria"]:
        lines.append(f"<tr><td>{e(k)} failed (alone)</td>"
                     + "".join(f"<td>{c['failed'][k]['runs']} ({c['failed'][k]['alone']})</td>" for c in cals.values())
                     + "</tr>")
    several = [c["runs"] - c["passed"] - c["spun"] - sum(f["alone"] for f in c["failed"].values()) for c in cals.values()]
    if s["criteria"]:
        lines.append("<tr><td>failed several criteria</td>" + "".join(f"<td>{x}</td>" for x in several) + "</tr>")
    return ("<h2>Why runs failed</h2><table><tr><th></th>" + head + "</tr>" + "".join(lines) + "</table>")


def _rate(x: float | None, fmt: str = ".4f") -> str:
    return "&ndash;" if x is None else format(x, fmt)


def _cell(x: Any) -> str:
    if x is None:
        return "&ndash;"
    return f"{x:.4g}" if isinstance(x, float) else html.escape(str(x))
