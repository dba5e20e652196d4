"""Figures of the rigs' identification (``idm-rs rig-fit --plots``) and diagnosis (``idm-rs
diagnose FILE.mat --plots``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..diagnosis.thresholds import BIC_THRESHOLD
from .diagnosis import NULL_SIGMAS, RigDiagnosis
from .fit import RESIDUAL_UNITS, RigFit


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_rig_fit(fit: RigFit, directory: Any) -> list[Any]:
    """Measured vs simulated position and force, and their residuals (one PNG); the title says
    whether the identified model describes the record (``RigFit.judgement``)."""
    plt = _pyplot()
    if not fit.arrays:
        return []
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    a = fit.arrays
    if "q" not in a:  # a force record (spring-slider)
        fig, (ax, axr) = plt.subplots(2, 1, figsize=(10, 6), sharex=True, constrained_layout=True)
        ax.plot(a["t"], a["force"], color="0.3", lw=1.5, alpha=0.5, label="measured (median-filtered)")
        ax.plot(a["t"], a["force_sim"], color="C3", lw=0.9, label="simulated (rig mechanism, fitted mu_s, mu_k)")
        ax.set_ylabel("spring force [N]")
        ax.legend(fontsize=8)
        axr.plot(a["t"], a["force"] - a["force_sim"], color="C3", lw=0.7)
        axr.set_ylabel("residual [N]")
        axr.set_xlabel("time t [s]")
        for x in (ax, axr):
            x.grid(alpha=0.3)
        m = fit.metrics
        ax.set_title(f"{fit.name}: mu_s = {fit.params['mu_s']:.4f}, mu_k = {fit.params['mu_k']:.4f}; period measured "
                     f"{m['period_s']:.3g} s, simulated {m.get('simulated_period_s', math.nan):.3g} s", fontsize=9)
        return [_save_fit(fig, fit, out)]
    if "force" not in a:  # a displacement record (frame)
        fig, (ax, axr) = plt.subplots(2, 1, figsize=(10, 6), sharex=True, constrained_layout=True)
        ax.plot(a["t"], a["drive"] * 1e3, color="0.6", lw=0.8, label="base (drive)")
        ax.plot(a["t"], a["q"] * 1e3, color="0.3", lw=1.5, alpha=0.6, label="top plate, measured")
        ax.plot(a["t"], a["q_sim"] * 1e3, color="C3", lw=0.9, label="top plate, simulated")
        ax.set_ylabel("displacement [mm]")
        ax.legend(fontsize=8)
        axr.plot(a["t"], (a["q"] - a["q_sim"]) * 1e3, color="C3", lw=0.7)
        axr.set_ylabel("residual [mm]")
        axr.set_xlabel("time t [s]")
        for x in (ax, axr):
            x.grid(alpha=0.3)
        p = fit.params
        ax.set_title(f"{fit.name}: f0 = {p['f0_Hz']:.3g} Hz, zeta = {p['zeta']:.3g}, "
                     f"Fc/k = {p['fc_over_k_m'] * 1e3:.3g} mm;"
                     f" simulated position error {fit.metrics.get('position_relative_error_pct', math.nan):.3g} %",
                     fontsize=9)
        return [_save_fit(fig, fit, out)]
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True, constrained_layout=True)
    axes[0].plot(a["t"], a["q"] * 1e3, color="0.3", lw=2, alpha=0.5, label="measured")
    axes[0].plot(a["t"], a["q_sim"] * 1e3, color="C3", lw=0.9, label="simulated (closed loop)")
    axes[0].set_ylabel("position [mm]")
    axes[0].legend(fontsize=8)
    axes[1].plot(a["t"], (a["q"] - a["q_sim"]) * 1e3, color="C3", lw=0.7)
    axes[1].set_ylabel("position error [mm]")
    axes[2].plot(a["t"], a["force"], color="0.3", lw=1.5, alpha=0.5, label="measured gtau vir")
    axes[2].plot(a["t"], a["force_sim"], color="C0", lw=0.7, label="simulated")
    axes[2].set_ylabel("motor force [N]")
    axes[2].legend(fontsize=8)
    axes[3].plot(a["t"], a["force"] - a["force_sim"], color="C0", lw=0.6)
    axes[3].set_ylabel("force error [N]")
    axes[3].set_xlabel("time t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    m = fit.metrics
    axes[0].set_title(f"{fit.name}: m = {fit.params['m']:.2f} kg, fc = {fit.params['fc']:.2f} N, "
                      f"fv = {fit.params['fv']:.1f} N s/m, offset = {fit.params['offset']:.2f} N; relative error "
                      f"position {m.get('position_relative_error_pct', math.nan):.3g} %, "
                      f"force {m.get('force_relative_error_pct', math.nan):.3g} %", fontsize=9)
    return [_save_fit(fig, fit, out)]


def _save_fit(fig: Any, fit: RigFit, out: Path) -> Path:
    """The fit figure with its judgement on top, written as ``rig_fit_<name>.png`` in ``out``."""
    import matplotlib.pyplot as plt

    _judgement(fig, fit)
    path = out / f"rig_fit_{fit.name}.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _judgement(fig: Any, fit: RigFit) -> None:
    """The fit's judgement as the figure's first line (red where the model does not describe)."""
    import textwrap

    if fit.judgement:
        head = {True: "describes the record", False: "DOES NOT DESCRIBE THE RECORD", None: "not judged"}[fit.describes]
        fig.suptitle(textwrap.fill(f"{head}: {fit.judgement}", 150), fontsize=8.5,
                     color="C3" if fit.describes is False else "0.2")


def plot_rig_diagnosis(d: RigDiagnosis, directory: Any) -> list[Path]:
    """The rig diagnosis's figures: ``rig_residual_<name>.png`` — the identified model's residual
    (and with the verdict's effect refitted) against time, position and velocity (bin means
    with the white-noise band), or for the spring–slider the slip-onset forces against the
    stick time and the time of the record; ``rig_ranking_<name>.png`` — each candidate's BIC
    gain, coloured by whether it could be named."""
    plt = _pyplot()
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    a = d.arrays
    unit = RESIDUAL_UNITS.get(d.rig, "")
    paths = []
    if "residual" in a:
        after = d.verdict not in ("none", "unexplained", "not_converged")
        if d.rig == "spring_slider":
            fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
            ax1.semilogx(a["t_stick"], a["fs"], ".", color="0.3", ms=3)
            ax1.set_xlabel("stick time before the slip [s]")
            ax2.plot(a["t_onset"], a["fs"], ".", color="0.3", ms=3, label="onset force")
            if after:
                fit_line = a["fs"] - a["residual_after"]
                # each model drawn against its own variable: aging against the stick time, a
                # drift against the time of the record (against the other it is a scribble)
                if d.verdict == "stick_time_aging":
                    order = np.argsort(a["t_stick"])
                    ax1.semilogx(a["t_stick"][order], fit_line[order], color="C3", lw=1.2, label=d.verdict)
                    ax1.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, 1.0))
                else:
                    detrended = a["fs"] - (fit_line - fit_line.mean())
                    ax1.semilogx(a["t_stick"], detrended, ".", color="C3", ms=3, alpha=0.7,
                                 label=f"less the {d.verdict.replace('_', ' ')}")
                    ax1.legend(fontsize=8, loc="lower left", bbox_to_anchor=(0.0, 1.0), frameon=False)
                order = np.argsort(a["t_onset"])
                ax2.plot(a["t_onset"][order], fit_line[order], color="C3", lw=1.2, label=d.verdict)
            for ax in (ax1, ax2):
                ax.set_ylabel("slip onset force [N]")
                ax.grid(alpha=0.3)
            ax2.set_xlabel("time of the slip [s]")
            ax2.legend(fontsize=8, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2, frameon=False)
        else:
            fig, axes = plt.subplots(3, 1, figsize=(10, 9), constrained_layout=True)
            e0, e1 = a["residual"], a["residual_after"]
            # markers, not lines: the rows may skip stretches (the frame's stuck samples)
            axes[0].plot(a["t"], e0, ".", color="0.4", ms=1.5, label="identified model")
            if after:
                axes[0].plot(a["t"], e1, ".", color="C3", ms=1.5, alpha=0.7, label=f"with {d.verdict}")
            axes[0].set_xlabel("time t [s]")
            for ax, x, name in ((axes[1], a["q"], "position [m]"), (axes[2], a["v"], "velocity [m/s]")):
                edges = np.linspace(x.min(), x.max(), 41)
                idx = np.clip(np.digitize(x, edges) - 1, 0, 39)
                centres = 0.5 * (edges[1:] + edges[:-1])
                for e, colour, label in ((e0, "0.3", "identified model"), (e1, "C3", f"with {d.verdict}")):
                    if e is e1 and not after:
                        continue
                    means = np.array([e[idx == k].mean() if np.any(idx == k) else np.nan for k in range(40)])
                    ax.plot(centres, means, ".-", color=colour, lw=1, ms=4, label=f"{label} (bin means)")
                ax.set_xlabel(name)
            for ax in axes:
                if d.noise_rms > 0:
                    ax.axhspan(-d.noise_rms, d.noise_rms, color="C0", alpha=0.12, lw=0, label="± white-noise RMS")
                ax.set_ylabel(f"residual [{unit}]")
                ax.grid(alpha=0.3)
                ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside, not over, the data
        fig.suptitle(f"{d.rig} {d.name}: {d.verdict} — RMS {d.rms_before:.4g} -> {d.rms_after:.4g} {unit}, "
                     f"noise {d.noise_rms:.3g} {unit}", fontsize=9.5)
        path = out / f"rig_residual_{d.name}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    if d.ranking:
        fig, ax = plt.subplots(figsize=(8, 0.5 * len(d.ranking) + 1.5), constrained_layout=True)
        names = [c.effect for c in d.ranking][::-1]
        gains = [c.delta_bic for c in d.ranking][::-1]
        colours = ["C2" if c.significant else "0.65" for c in d.ranking][::-1]
        ax.barh(names, gains, color=colours)
        ax.axvline(BIC_THRESHOLD, color="C3", ls="--", lw=1, label="ΔBIC threshold")
        ax.set_xscale("symlog", linthresh=BIC_THRESHOLD)
        ax.set_xlabel("ΔBIC against the identified model (symlog)")
        ax.set_title(f"{d.name}: candidates (green: amplitudes beyond {NULL_SIGMAS:g} σ with the physical sign; "
                     "grey: not nameable)", fontsize=9)
        ax.legend(fontsize=8)
        path = out / f"rig_ranking_{d.name}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths
