"""Figures 8, 9 and 10 as CSV and PNG files (matplotlib, from the ``plot`` extra).

Files are written to a temporary name in the target directory and renamed into place, so an
interrupted run never leaves a half-written file under the final name.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from firmware_py.platform.files import write_files
from sim_plant.offline.closed_loop import Trace
from sim_plant.offline.paper import CONDITIONS, FIG10_CONDITION, PAPER_M_Z, Condition, PaperRun

CSV_STEP = 1e-3  # s between CSV/plot samples (the reference is solved on a finer grid)


def write_all(run: PaperRun, out_dir: Path) -> list[Path]:
    """Render every figure first, then write them; returns the paths written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files: dict[str, bytes] = {}
    for name, columns in _figure_columns(run).items():
        files[f"{name}.csv"] = _csv_bytes(columns)
    files.update(_render_pngs(run))
    return write_files(out_dir, files)


def _figure_columns(run: PaperRun) -> dict[str, dict[str, np.ndarray]]:
    fig8: dict[str, np.ndarray] = {}
    fig9: dict[str, np.ndarray] = {}
    for c in CONDITIONS:
        for kind in ("controlled", "conventional"):
            tr = run.steer[c.key][kind]
            fig8.setdefault("t_s", _decimate(tr, tr.t))
            fig8[f"{c.key}_{kind}_yaw_rate_norm"] = _decimate(tr, tr.yaw_rate)
            tr = run.disturbance[c.key][kind]
            fig9.setdefault("t_s", _decimate(tr, tr.t))
            fig9[f"{c.key}_{kind}_yaw_rate_rad_s"] = _decimate(tr, tr.yaw_rate)
        fig9[f"{c.key}_controlled_aux_steer_deg"] = np.degrees(_decimate(tr, run.disturbance[c.key]["controlled"].aux))
    fig10: dict[str, np.ndarray] = {}
    for form, tr in run.fig10.items():
        fig10.setdefault("t_s", _decimate(tr, tr.t))
        fig10[f"{form}_aux_steer_deg"] = np.degrees(_decimate(tr, tr.aux))
    return {"fig8_steering_step": fig8, "fig9_yaw_moment_step": fig9, "fig10_aux_steer": fig10}


def _decimate(tr: Trace, x: np.ndarray) -> np.ndarray:
    every = max(1, int(round(CSV_STEP / (tr.t[1] - tr.t[0]))))
    return x[::every]


def _csv_bytes(columns: dict[str, np.ndarray]) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    names = list(columns)
    w.writerow(names)
    for row in zip(*(columns[n] for n in names)):
        w.writerow([f"{x:.9g}" for x in row])
    return buf.getvalue().encode()


def _render_pngs(run: PaperRun) -> dict[str, bytes]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pngs: dict[str, bytes] = {}
    for name, source, ylabel, title in (
        ("fig8_steering_step.png", run.steer, "yaw rate (normalised)", "Figure 8: driver steering step"),
        ("fig9_yaw_moment_step.png", run.disturbance, "yaw rate [rad/s]",
         f"Figure 9: {PAPER_M_Z:.0f} Nm yaw moment step"),
    ):
        fig, axes = plt.subplots(len(CONDITIONS) // 2, 2, figsize=(10, 8), sharex=True, squeeze=False)
        for i, c in enumerate(CONDITIONS):
            ax = axes[i // 2][i % 2]
            for kind, style in (("controlled", "-"), ("conventional", "--")):
                tr = source[c.key][kind]
                ax.plot(_decimate(tr, tr.t), _decimate(tr, tr.yaw_rate), style, label=kind)
            ax.set_title(c.label, fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.set_ylabel(ylabel, fontsize=8)
        for ax in axes[-1]:
            ax.set_xlabel("time [s]")
        axes[0][0].legend(fontsize=8)
        fig.suptitle(title)
        fig.tight_layout()
        pngs[name] = _png(fig, plt)

    fig, ax = plt.subplots(figsize=(7, 4))
    for form, style in (("limited", "-"), ("standard", "--")):
        tr = run.fig10[form]
        ax.plot(_decimate(tr, tr.t), np.degrees(_decimate(tr, tr.aux)), style,
                label=f"{form} (peak {math.degrees(float(np.max(np.abs(tr.aux)))):.2f} deg)")
    limit = 3.0
    ax.axhline(-limit, color="k", lw=0.8, ls=":")
    ax.axhline(limit, color="k", lw=0.8, ls=":")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("auxiliary steering delta_mr [deg]")
    ax.set_title(f"Figure 10: auxiliary actuator output, {Condition(*FIG10_CONDITION).label}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    pngs["fig10_aux_steer.png"] = _png(fig, plt)
    return pngs


def _png(fig, plt) -> bytes:  # type: ignore[no-untyped-def]
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


