"""Figures of a diagnosis (matplotlib, Agg): the fit per experiment with its residual and the
systematic windows shaded, where the residual lives (experiment x phase), the candidate ranking,
and the RMS story against the noise floor."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Union, cast

import numpy as np

from .locate import PHASES
from .thresholds import BIC_THRESHOLD, NOISE_RATIO_OK

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from numpy.typing import NDArray

    from .discovery.library import Trajectory
    from .fitting import FitResult
    from .results import Candidate, Diagnosis

DPI = 120
C_DATA = "0.45"
C_NOMINAL = "tab:red"
C_CALIBRATED = "tab:orange"
C_REFIT = "tab:blue"
C_WINDOW = "tab:red"
PHASE_COLOURS = {"rest": "0.6", "rapid edge / slip": "tab:purple", "slow edge / stick": "tab:green"}


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def refit_candidate(d: Diagnosis) -> Optional[Candidate]:
    """The candidate the plots show as the refitted model: the verdict's, when it names an effect."""
    c = d.verdict_candidate
    return c if c is not None and c.spec is not None else None


#: fewest samples of rest before the drive that pin the sensor offset on their own
MIN_REST_SAMPLES = 5


def _aligned(x: np.ndarray, pred: np.ndarray, rest: Optional[np.ndarray] = None) -> tuple[np.ndarray, float]:
    """(prediction shifted by the sensor offset, that offset) [m]. The offset is measured where
    the body is at rest before the drive (``rest``, a mask) when there are enough such samples:
    there every model agrees, so a model that drifts later is not shifted to meet the data half
    way (which would draw it off before the drive starts); otherwise over the whole record."""
    if not np.any(np.isfinite(pred)):
        return pred, math.nan
    use = rest if rest is not None and int(np.count_nonzero(rest)) >= MIN_REST_SAMPLES else slice(None)
    off = float(np.nanmean((x - pred)[use]))
    return pred + off, off


def _rest_before_drive(voltage: np.ndarray) -> np.ndarray:
    """Mask of the samples before the drive voltage first leaves 0."""
    moving = np.flatnonzero(np.abs(voltage) > 0)
    mask = np.zeros(voltage.shape, dtype=bool)
    mask[: moving[0] if moving.size else voltage.size] = True
    return mask


def _save(fig: "Figure", path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


#: the residual's systematic part: a moving mean over this share of a drive cycle
SMOOTH_CYCLE_SHARE = 1.0 / 25.0


def _moving_mean(r: np.ndarray, w: int) -> np.ndarray:
    """Centred moving mean over `w` samples (shorter windows at the ends)."""
    if w <= 1 or r.size < w:
        return cast("np.ndarray", r.copy())
    c = np.cumsum(np.insert(r, 0, 0.0))
    half = w // 2
    lo = np.clip(np.arange(r.size) - half, 0, r.size)
    hi = np.clip(np.arange(r.size) - half + w, 0, r.size)
    return cast("np.ndarray", (c[hi] - c[lo]) / (hi - lo))


def report_residuals(d: Diagnosis, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Experiment `j`'s residuals [m] as the report computes them (data − model − each drive
    cycle's fitted segment offset): of the calibrated nominal and of the refitted model (the
    calibrated one again when no effect is named). Empty where the result kept none."""
    cal = np.asarray(d.calibrated_residuals[j]) if j < len(d.calibrated_residuals) else np.zeros(0)
    cand = refit_candidate(d)
    found = _discovered_refit(d)
    if found is not None:
        return cal, np.asarray(found.residuals[j]) if j < len(found.residuals) else cal
    ref = np.asarray(cand.residuals[j]) if cand is not None and j < len(cand.residuals) else cal
    return cal, ref


def _discovered_refit(d: Diagnosis) -> Optional[FitResult]:
    """The refit of a discovered term (verdict "discovered"), else None."""
    f = getattr(d, "discovery", None)
    return f.refit if d.verdict.endswith("discovered") and f is not None and f.refit is not None else None


def plot_fits(d: Diagnosis, directory: Path) -> list[Path]:
    """``fit_<experiment>.png``: voltage; data vs nominal vs refitted model; the residuals of the
    calibrated nominal and of the refitted model *as the report computes them* (each drive
    cycle's segment less its own fitted offset, so their RMS is the report's), faint, with
    their systematic part (a moving mean over 1/25 of a drive cycle) bold against the noise
    band and that band narrowed to the moving mean's own noise; the located windows shaded."""
    import matplotlib.pyplot as plt

    if d.simulator is None or d.nominal_spec is None or d.calibrated_spec is None:
        return []
    cand = refit_candidate(d)
    found = _discovered_refit(d)
    refit_spec = found.spec if found is not None else cand.spec if cand is not None else None
    specs = [d.nominal_spec, d.calibrated_spec] + ([refit_spec] if refit_spec is not None else [])
    preds = d.simulator.predict(specs)
    refit_label = ("with the discovered term (refit)" if found is not None
                   else f"with {cand.effect} (refit)" if cand is not None else "calibrated nominal")
    sigma_nm = d.noise.sigma * 1e9
    paths = []
    for j, e in enumerate(d.recording.experiments):
        t_ms = e.t * 1e3
        x = e.x
        p_nom, p_cal = preds[0][j], preds[1][j]
        p_ref = preds[2][j] if refit_spec is not None else p_cal
        rest = _rest_before_drive(np.asarray(e.voltage))
        ref_aligned, off_ref = _aligned(x, p_ref, rest)
        if not math.isfinite(off_ref):
            off_ref = float(np.mean(x))
        nom_aligned, _ = _aligned(x, p_nom, rest)
        cal_aligned, _ = _aligned(x, p_cal, rest)
        # the report's residuals (per-segment offsets removed); the rest-aligned difference
        # only where a result kept none
        r_cal, r_ref = report_residuals(d, j)
        r_cal = r_cal * 1e9 if r_cal.size == x.size else (x - cal_aligned) * 1e9
        r_ref = r_ref * 1e9 if r_ref.size == x.size else (x - ref_aligned) * 1e9
        per_cycle = d.recording.sample_rate_Hz / e.frequency_Hz if e.frequency_Hz > 0 else x.size
        span = max(1, int(round(SMOOTH_CYCLE_SHARE * per_cycle)))  # samples of the moving mean

        fig, (ax_v, ax_x, ax_r) = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True,
                                               gridspec_kw={"height_ratios": [1, 3, 2]}, constrained_layout=True)
        ax_v.plot(t_ms, e.voltage, color="0.3", lw=1)
        ax_v.set_ylabel("voltage [V]")
        ax_v.set_title(f"{d.case} / {e.name}: {e.direction}, {e.amplitude_V:g} V, {e.frequency_Hz:g} Hz, "
                       f"{e.cycles} cycles — verdict: {d.verdict}")
        scale, unit = (1e6, "µm") if np.ptp(x) > 2e-6 else (1e9, "nm")
        ax_x.plot(t_ms, (x - off_ref) * scale, color=C_DATA, lw=3.0, alpha=0.45, label="data (offset removed)")
        ax_x.plot(t_ms, (nom_aligned - off_ref) * scale, color=C_NOMINAL, lw=1.2, ls="--", label="nominal (meta.json)")
        if refit_spec is not None:
            ax_x.plot(t_ms, (cal_aligned - off_ref) * scale, color=C_CALIBRATED, lw=1.0, ls=":",
                      label="calibrated nominal")
        ax_x.plot(t_ms, (ref_aligned - off_ref) * scale, color=C_REFIT, lw=1.2, label=refit_label)
        ax_x.set_ylabel(f"main body x1 [{unit}]")
        ax_x.legend(loc="best", fontsize=8)
        ax_x.grid(alpha=0.3)

        for w in d.windows:
            if w.experiment == e.name:
                for ax in (ax_x, ax_r):
                    ax.axvspan(w.t_start * 1e3, w.t_end * 1e3, color=C_WINDOW, alpha=0.12, lw=0)
        ax_r.axhspan(-sigma_nm, sigma_nm, color="0.85", alpha=0.6, lw=0, label=f"±1σ noise ({sigma_nm:.2f} nm)")
        band = sigma_nm / math.sqrt(span)
        ax_r.axhspan(-band, band, color="0.6", alpha=0.5, lw=0, label=f"±1σ of the moving mean ({band:.2f} nm)")
        ax_r.plot(t_ms, r_cal, color=C_CALIBRATED, lw=0.5, alpha=0.35)
        ax_r.plot(t_ms, _moving_mean(r_cal, span), color=C_CALIBRATED, lw=1.6,
                  label=f"calibrated nominal (RMS {np.sqrt(np.nanmean(r_cal ** 2)):.2f} nm; bold: systematic part)")
        if refit_spec is not None:
            ax_r.plot(t_ms, r_ref, color=C_REFIT, lw=0.5, alpha=0.35)
            ax_r.plot(t_ms, _moving_mean(r_ref, span), color=C_REFIT, lw=1.6,
                      label=f"{refit_label} (RMS {np.sqrt(np.nanmean(r_ref ** 2)):.2f} nm)")
        if any(w.experiment == e.name for w in d.windows):
            ax_r.axvspan(np.nan, np.nan, color=C_WINDOW, alpha=0.12, lw=0, label="systematic windows (calibrated)")
        ax_r.axhline(0, color="0.3", lw=0.5)
        ax_r.set_ylabel("residual [nm]\n(data − model − segment offset)")
        ax_r.set_xlabel("time [ms]")
        # below the panel: the residual fills its axes, and a legend inside covered it
        ax_r.legend(loc="upper center", bbox_to_anchor=(0.5, -0.32), fontsize=8, ncol=2, frameon=False)
        ax_r.grid(alpha=0.3)
        paths.append(_save(fig, directory / f"fit_{_safe(e.name)}.png"))
    return paths


def plot_residual_phases(d: Diagnosis, directory: Path) -> Path:
    """``residual_phases.png``: share of the excess residual energy of the calibrated model by
    experiment and motion phase, RMS / noise written on each bar, systematic cells outlined."""
    import matplotlib.pyplot as plt

    names = [e.name for e in d.recording.experiments]
    cells = {(cell.experiment, cell.phase): cell for cell in d.locations if cell.phase in PHASES}
    fig, ax = plt.subplots(figsize=(max(6.0, 1.9 * len(names) + 2), 4.5), constrained_layout=True)
    width = 0.8 / len(PHASES)
    x = np.arange(len(names))
    for k, phase in enumerate(PHASES):
        shares, ratios, sys_ = [], [], []
        for n in names:
            cell = cells.get((n, phase))
            shares.append(100 * cell.excess_share if cell else 0.0)
            ratios.append(cell.rms_over_noise if cell else math.nan)
            sys_.append(bool(cell and cell.systematic))
        pos = x + (k - (len(PHASES) - 1) / 2) * width
        bars = ax.bar(pos, shares, width, color=PHASE_COLOURS.get(phase), label=phase,
                      edgecolor=["black" if s else "none" for s in sys_], linewidth=1.2)
        for b, r in zip(bars, ratios):
            if math.isfinite(r):
                ax.annotate(f"{r:.1f}×", (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom",
                            fontsize=7, xytext=(0, 2), textcoords="offset points")
    ax.set_xticks(x, names, rotation=15, ha="right", fontsize=8)
    ax.set_ylabel("share of excess residual energy [%]")
    ax.set_title(f"{d.case}: where the calibrated model's residual lives\n"
                 f"(label: RMS / noise; black outline: systematic; noise {d.noise.sigma * 1e9:.2f} nm)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    ax.set_ylim(0, max(5.0, ax.get_ylim()[1] * 1.1))
    return _save(fig, directory / "residual_phases.png")


def plot_ranking(d: Diagnosis, directory: Path) -> Path:
    """``ranking.png``: ΔBIC of every candidate (symlog), RMS after / noise and held-out RMS
    written beside each bar, the verdict highlighted, score-only (not fitted) bars hatched, the
    same vocabulary as the report: "fitted", "at null", "score only"."""
    import matplotlib.pyplot as plt

    cands = list(d.ranking)
    sigma = d.noise.sigma
    fig, ax = plt.subplots(figsize=(10, 0.45 * len(cands) + 1.8), constrained_layout=True)
    y = np.arange(len(cands))[::-1]
    vals = np.array([c.delta_bic for c in cands], dtype=float)
    colours = [C_REFIT if c.effect == d.verdict else ("0.75" if c.screened_only else "0.5") for c in cands]
    # a candidate no better than the null is "not supported" in the report: no bar here either
    bars = ax.barh(y, np.clip(np.nan_to_num(vals), 0.0, None), color=colours, hatch=None)
    for b, c in zip(bars, cands):
        if c.screened_only:
            b.set_hatch("//")
            b.set_edgecolor("0.4")
    ax.set_xscale("symlog", linthresh=max(BIC_THRESHOLD, 1.0))
    ax.axvline(BIC_THRESHOLD, color="tab:green", ls="--", lw=1, label=f"ΔBIC threshold ({BIC_THRESHOLD:g})")
    ax.axvline(0, color="0.2", lw=0.8)
    ax.set_yticks(y, [c.effect + ("" if c.fit_label == "fitted" else f" ({c.fit_label})") for c in cands], fontsize=9)
    if any(c.screened_only for c in cands):
        ax.barh(np.nan, 0, color="0.75", hatch="//", edgecolor="0.4",
                label="score only: not fitted, its linearised ΔBIC")
    lo, hi = ax.get_xlim()
    ax.set_xlim(lo, hi * 10 if hi > 0 else hi)
    for yi, c in zip(y, cands):
        ratio = c.rms_over_noise(sigma)
        text = f"ΔBIC {c.delta_bic_words}, " + (f"RMS {ratio:.2f}× noise" if math.isfinite(ratio)
                                                  else f"not fitted (score {c.score:.0f})")
        if math.isfinite(c.heldout_rms):
            text += f", held-out {c.heldout_rms * 1e9:.2f} nm"
        xpos = max(c.delta_bic, 0.0) if math.isfinite(c.delta_bic) else 0.0
        ax.annotate(text, (xpos, yi), xytext=(4, 0), textcoords="offset points", va="center", fontsize=8)
    ax.set_xlabel("ΔBIC against the best null fit (symlog; > 0: better)")
    ax.set_title(f"{d.case}: candidate effects — verdict: {d.verdict}")
    # under the axes, outside them: inside, it covered the last row's bar and numbers
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    ax.grid(axis="x", alpha=0.3)
    return _save(fig, directory / "ranking.png")


def plot_rms_story(d: Diagnosis, directory: Path) -> Path:
    """``rms_story.png``: residual RMS of the nominal, calibrated and refitted models against the
    noise floor (band: the noise estimate's ±1σ uncertainty)."""
    import matplotlib.pyplot as plt

    sigma = d.noise.sigma
    cand = refit_candidate(d)
    found = _discovered_refit(d)
    labels = ["nominal\n(meta.json)"]
    values = [d.rms_before]
    colours = [C_NOMINAL]
    hatches: list[Optional[str]] = [None]
    if math.isfinite(d.rms_calibrated):  # an interrupted run may stop before the calibration
        labels.append("calibrated\nnominal")
        values.append(d.rms_calibrated)
        colours.append(C_CALIBRATED)
        hatches.append(None)
    if found is not None:
        assert d.discovery is not None  # found is its refit
        labels.append("with the\ndiscovered term")
        values.append(d.discovery.rms_after)
        colours.append(C_REFIT)
        hatches.append(None)
    elif not d.complete:
        pass  # no verdict was reached: no refit to show
    elif cand is not None:
        labels.append(f"with\n{cand.effect}")
        values.append(cand.rms_after)
        colours.append(C_REFIT)
        hatches.append(None)
    else:
        # no effect accepted: show the best refitted candidate, marked as not accepted
        tried = next((c for c in d.ranking if not c.screened_only and math.isfinite(c.rms_after)), None)
        if tried is not None:
            labels.append(f"best candidate\n{tried.effect}\n(not accepted)")
            values.append(tried.rms_after)
            colours.append("0.75")
            hatches.append("//")
    vals_nm = np.array(values) * 1e9
    fig, ax = plt.subplots(figsize=(6.5, 4.5), constrained_layout=True)
    bars = ax.bar(range(len(values)), vals_nm, color=colours, width=0.6)
    for b, h in zip(bars, hatches):
        if h:
            b.set_hatch(h)
            b.set_edgecolor("0.4")
    log = bool(np.nanmax(vals_nm) / (sigma * 1e9) > 20)
    if log:
        ax.set_yscale("log")
    rel = d.noise.relative_uncertainty
    ax.axhspan(sigma * 1e9 * (1 - rel), sigma * 1e9 * (1 + rel), color="0.6", alpha=0.5, lw=0)
    ax.axhline(sigma * 1e9, color="0.2", lw=1, label=f"noise floor {sigma * 1e9:.2f} nm")
    ax.axhline(NOISE_RATIO_OK * sigma * 1e9, color="tab:green", ls="--", lw=1,
               label=f"{NOISE_RATIO_OK:g} × noise (explained)")
    for b, v in zip(bars, vals_nm):
        ax.annotate(f"{v:.2f} nm\n{v / (sigma * 1e9):.2f}× noise", (b.get_x() + b.get_width() / 2, v),
                    ha="center", va="bottom", fontsize=8, xytext=(0, 2), textcoords="offset points")
    ax.set_xticks(range(len(values)), labels)
    ax.set_ylabel("residual RMS [nm]")
    top = ax.get_ylim()[1]
    if log:
        ax.set_ylim(0.5 * sigma * 1e9, top * 3)
    else:
        ax.set_ylim(0, top * 1.2)
    ax.set_title(f"{d.case}: residual RMS — verdict: {d.verdict}")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, directory / "rms_story.png")


def plot_diagnosis(d: Diagnosis, directory: Union[str, Path]) -> list[Path]:
    """Write every figure of the diagnosis `d` into `directory` (created); returns their paths.
    An interrupted diagnosis gets the figures of what it finished (none before its calibration).

    Parameters
    ----------
    d : Diagnosis
        What :func:`idm_rs.diagnose` returned.
    directory : path
        Where the PNG files go (created if missing).

    Returns
    -------
    list of Path
        ``fit_<experiment>.png`` per experiment (data, nominal, calibrated and refitted model,
        residuals with the systematic windows), ``residual_phases.png``, ``ranking.png``,
        ``rms_story.png``, and ``discovery.png`` when discovery ran.

    Examples
    --------
    >>> idm_rs.plot_diagnosis(d, "plots")   # doctest: +SKIP
    """
    import matplotlib

    matplotlib.use("Agg")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = plot_fits(d, directory)  # none before the calibration finished
    # an interrupted diagnosis plots what it finished, nothing it did not compute
    if d.locations:
        paths.append(plot_residual_phases(d, directory))
    if d.ranking:
        paths.append(plot_ranking(d, directory))
    if math.isfinite(d.rms_before):
        paths.append(plot_rms_story(d, directory))
    discovery = getattr(d, "discovery", None)
    if discovery is not None and discovery.form is not None:
        paths.append(plot_discovery(d, directory))
    return paths


#: each library variable along a trajectory, and its display scale and unit
_VARIABLES: dict[str, tuple[Callable[[Trajectory], NDArray[np.float64]], float, str]] = {
    "x1": (lambda tr: tr.x1, 1e6, "µm"), "v1": (lambda tr: tr.v1, 1e3, "mm/s"),
    "x2": (lambda tr: tr.x2, 1e6, "µm"), "v2": (lambda tr: tr.v2, 1e3, "mm/s"),
    "x1 - x2": (lambda tr: tr.x1 - tr.x2, 1e6, "µm"), "x2 - x1": (lambda tr: tr.x2 - tr.x1, 1e6, "µm"),
    "v1 - v2": (lambda tr: tr.v1 - tr.v2, 1e3, "mm/s"), "v2 - v1": (lambda tr: tr.v2 - tr.v1, 1e3, "mm/s"),
    "Ff": (lambda tr: tr.ff, 1.0, "N"), "V": (lambda tr: tr.volt, 1.0, "V"), "t": (lambda tr: tr.t, 1e3, "ms"),
}


def plot_discovery(d: Diagnosis, directory: Path) -> Path:
    """``discovery.png``: per experiment, the force inferred through the simulator (knots) against
    the found term at its refitted coefficients, both on the knots (the term projected there, as
    the regression compared them), with the share of the force the data can see (the force's
    knots weighted by what their derivatives move) as the band's shade; and beside it the same
    against the found form's variable (x1, v1, V, ...): a force periodic in the position or
    quadratic in the velocity reads there, not against time."""
    import matplotlib.pyplot as plt

    from .discovery import library_columns

    f = d.discovery
    assert f is not None and f.form is not None  # plot_diagnosis draws this for a found form only
    force = f.forces[f.body]
    form = f.form
    values = {n: v for n, (v, _) in f.values.items()} if f.values else dict(form.coefficients)
    wl = values.get("lib_wavelength", form.wavelength)
    variable = next((v for v in form.variables if v in _VARIABLES and v != "t"), None)
    n_exp = len(force.values)
    cols = 2 if variable is not None else 1
    fig, axes = plt.subplots(n_exp, cols, figsize=(9.5 if cols == 1 else 13.5, 2.2 * n_exp + 0.8), sharex=False,
                             squeeze=False, gridspec_kw={"width_ratios": [2, 1]} if cols == 2 else None)
    for j in range(n_exp):
        ax = axes[j, 0]
        tr = force.trajectories[j]
        k = force.knots[j]
        A = force.jacobians[j]
        n = A.shape[0]
        seen = np.sqrt(np.sum(A * A, axis=0))
        seen = seen / max(float(seen.max()), 1e-300)
        theta = library_columns(tr, form.terms, wl)[:n]
        term = theta @ np.array([values.get(t.param, 0.0) for t in form.terms])
        knot_term = force.on_knots(j, term)
        ax.plot(k * 1e3, force.values[j] * 1e3, "o-", ms=2.5, lw=1.0, color="0.3", label="inferred force")
        ax.plot(k * 1e3, knot_term * 1e3, "-", lw=1.6, color=C_REFIT,
                label=f"found term ({', '.join(t.symbol for t in form.terms)}), refitted, on the knots")
        ax.plot(tr.t[:n] * 1e3, term * 1e3, "-", lw=0.5, color=C_REFIT, alpha=0.2, label="found term, every sample")
        lo, hi = ax.get_ylim()
        for a, b, w in zip(k[:-1], k[1:], seen[:-1]):
            ax.axvspan(a * 1e3, b * 1e3, color="tab:green", alpha=0.18 * float(w), lw=0)
        ax.set_ylim(lo, hi)
        ax.set_ylabel("force [mN]")
        ax.set_title(d.recording.experiments[j].name, fontsize=9, loc="left")
        if j == 0:
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.08), ncol=3, frameon=False)
        if variable is not None:
            get, scale, unit = _VARIABLES[variable]
            axv = axes[j, 1]
            along = get(tr)[:n]
            at_knots = np.interp(k, tr.t[:n], along)
            axv.plot(at_knots * scale, force.values[j] * 1e3, "o", ms=2.5, color="0.3", alpha=0.7)
            # dots, not a line: a term such as Ff sin(2 pi x1/lambda) is no function of x1 alone
            axv.plot(along * scale, term * 1e3, ".", ms=1.0, color=C_REFIT, alpha=0.35)
            axv.set_ylim(lo, hi)
            axv.grid(alpha=0.3)
            if j == n_exp - 1:
                axv.set_xlabel(f"{variable} [{unit}]  (the found form's variable)")
    axes[-1, 0].set_xlabel("time [ms]  (green: where the readings see the force)")
    title = (f"{d.case}: the force on the {'main body' if f.body == 'main' else 'weight'} inferred from the "
             f"data, against the found term")
    fig.suptitle(title if len(title) <= 120 else title[:117] + "...", fontsize=9)
    fig.tight_layout()
    return _save(fig, directory / "discovery.png")
