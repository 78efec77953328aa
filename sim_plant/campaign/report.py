"""The report of a campaign's results: pass rates, maps, histograms and the worst cases.

``build(out)`` reads ``out``'s chunk files and writes into ``out/report/``:

* ``pass_map_<calibration>.png``: the pass rate over mu x v (10 x 10 bins), per calibration;
* ``hist_<metric>.png``: each judged figure's histogram, the calibrations overlaid, the
  criterion's bound drawn;
* ``index.html``: pass rates per criterion and calibration, per disturbance kind, the
  figures, and the ``WORST`` worst samples of each calibration by peak yaw rate with all their
  parameters (``mrsteer campaign export DIR INDEX`` replays one).

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
from sim_plant.campaign.spec import CRITERIA, parse

WORST = 10
BINS = 10


def summarise(out: Path) -> dict[str, Any]:
    """Pass rates (overall, per criterion, per disturbance kind) and the worst cases, per calibration."""
    c = parse((out / SPEC_FILE).read_text(), str(out / SPEC_FILE))
    cols = results.read_all(out).to_pydict()
    cal = np.asarray(cols["calibration"])
    summary: dict[str, Any] = {"campaign": c.name, "samples": c.samples, "criteria": c.criteria, "calibrations": {}}
    for name in c.calibrations:
        m = cal == name
        rows = {k: np.asarray(v)[m] for k, v in cols.items()}
        n = int(m.sum())
        per_kind = {k: float(np.mean(rows["pass"][rows["disturbance"] == k])) for k in KINDS
                    if np.any(rows["disturbance"] == k)}
        order = np.argsort(-rows["peak_yaw_rate"])[:WORST]
        worst = [{k: _plain(rows[k][i]) for k in (INDEX, *PARAMETERS, *METRICS)} for i in order]
        summary["calibrations"][name] = {
            "runs": n, "pass_rate": float(np.mean(rows["pass"])) if n else None,
            "per_criterion": {k: float(np.mean(rows[f"pass_{k}"])) for k in c.criteria},
            "per_disturbance": per_kind, "worst": worst,
            "figures": {k: {"median": float(np.median(rows[k])), "p99": float(np.percentile(rows[k], 99)),
                            "max": float(np.max(rows[k]))} for k in CRITERIA} if n else {},
        }
    return summary


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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = summarise(out)
    cols = {k: np.asarray(v) for k, v in results.read_all(out).to_pydict().items()}
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
        fig, ax = plt.subplots(figsize=(5.5, 4.0))
        for name in summary["calibrations"]:
            values = cols[metric][cols["calibration"] == name]
            # (a detection_time of inf, never reported, has no bin: the summary's max shows it)
            ax.hist(values[np.isfinite(values)], bins=50, alpha=0.5, label=name)
        bound = summary["criteria"].get(metric)
        if bound is not None:
            ax.axvline(bound, color="k", ls="--", label="criterion")
        unit = METRICS[metric][0]
        ax.set(xlabel=f"{metric} ({unit})" if unit else metric, ylabel="samples", yscale="log")
        ax.legend()
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
             f"<h1>Campaign {e(s['campaign'])}</h1><p>{s['samples']} samples per calibration; criteria: {crit}.</p>",
             "<h2>Pass rates</h2><table><tr><th>calibration</th><th>runs</th><th>all</th>"
             + "".join(f"<th>{e(k)}</th>" for k in s["criteria"]) + "".join(f"<th>{k}</th>" for k in KINDS) + "</tr>"]
    for name, c in s["calibrations"].items():
        parts.append(f"<tr><td>{e(name)}</td><td>{c['runs']}</td><td>{c['pass_rate']:.4f}</td>"
                     + "".join(f"<td>{c['per_criterion'][k]:.4f}</td>" for k in s["criteria"])
                     + "".join(f"<td>{c['per_disturbance'].get(k, float('nan')):.4f}</td>" for k in KINDS) + "</tr>")
    parts.append("</table>")
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


def _cell(x: Any) -> str:
    return f"{x:.4g}" if isinstance(x, float) else html.escape(str(x))
