"""Where and when the model and the recording disagree: residual energy per experiment, per
motion phase (rest, rapid edge and the slip that follows, slow edge where the body sticks and
presliding), and over time windows, each judged against the noise level."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Experiment, Recording
from .thresholds import SYSTEMATIC_Z, WINDOW_S

PHASES = ("rest", "rapid edge / slip", "slow edge / stick")


@dataclass(frozen=True)
class Location:
    """A place where the residual lives. `excess_share`: its share of the residual energy above
    the noise floor over the whole case; `z`: how far its residual energy lies above what noise
    alone gives (in standard deviations); `rms_over_noise`: its residual RMS / noise RMS."""

    experiment: str
    phase: str  #: a PHASES entry, or "window" for a time window
    t_start: float  #: [s]
    t_end: float  #: [s]
    n: int
    rms: float  #: [m]
    rms_over_noise: float
    excess_share: float
    z: float
    systematic: bool

    def to_dict(self) -> dict[str, Any]:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in self.__dict__.items()}


def phase_masks(e: Experiment) -> dict[str, NDArray[np.bool_]]:
    """Masks of the motion phases. The rapid phase is the fast edge plus as long again after it
    (the slip and the ringing that follow); the rest of each period is the slow edge."""
    t = e.t
    rest = t < e.rest_s - 1e-12
    if e.is_sampled:
        # no cycles: the input's fast changes (|dV/dt| above a fifth of its largest) and the rest
        rate = np.abs(np.gradient(e.voltage, t))
        fast = ~rest & (rate > 0.2 * rate.max()) if rate.max() > 0 else np.zeros_like(rest)
        return {"rest": rest, "rapid edge / slip": fast, "slow edge / stick": ~rest & ~fast}
    period = 1.0 / e.frequency_Hz
    fast_start = 0.0 if e.direction == "forward" else period - e.edge_s
    since = t - e.rest_s - fast_start  # time since the first fast edge began
    k = np.floor(since / period + 1e-9)
    rapid = (since >= -1e-12) & (k < e.cycles) & (since - k * period < 2 * e.edge_s - 1e-12)
    slow = ~rest & ~rapid
    return {"rest": rest, "rapid edge / slip": rapid, "slow edge / stick": slow}


def _judge(r: NDArray[np.float64], sigma: float) -> tuple[float, float]:
    """(excess energy above noise [m^2], z-score of the energy against noise alone)."""
    n = r.size
    if n == 0:
        return 0.0, 0.0
    e = float(np.sum(r * r))
    excess = e - n * sigma**2
    # for Gaussian noise, sum r^2 / sigma^2 ~ chi2(n): mean n, sd sqrt(2n)
    return excess, excess / (sigma**2 * math.sqrt(2.0 * n))


def locate(rec: Recording, residuals: Sequence[NDArray[np.float64]], sigma: float,
           window_s: float = WINDOW_S) -> tuple[list[Location], list[Location]]:
    """(per experiment x phase locations, time windows), both sorted by excess share."""
    items: list[tuple[Experiment, str, float, float, NDArray[np.float64]]] = []
    windows: list[tuple[Experiment, str, float, float, NDArray[np.float64]]] = []
    for e, r in zip(rec.experiments, residuals):
        masks = phase_masks(e)
        # anchor the offset on the rest segment (the body is known to be at rest there): with
        # the file mean as offset, an error later in the file would show up at rest too
        if masks["rest"].sum() > 2:
            r = r - r[masks["rest"]].mean()
        for phase, m in masks.items():
            if m.any():
                items.append((e, phase, float(e.t[m][0]), float(e.t[m][-1]), r[m]))
        n_per = max(int(round(window_s * rec.sample_rate_Hz)), 1)
        for s in range(0, r.size, n_per):
            sl = slice(s, min(s + n_per, r.size))
            windows.append((e, "window", float(e.t[sl][0]), float(e.t[sl][-1]), r[sl]))

    def build(group: list[tuple[Experiment, str, float, float, NDArray[np.float64]]]) -> list[Location]:
        judged = [(g, *_judge(g[4], sigma)) for g in group]
        total = sum(max(x, 0.0) for _, x, _ in judged) or 1.0
        out = []
        for (e, phase, t0, t1, r), excess, z in judged:
            rms = float(math.sqrt(np.mean(r * r))) if r.size else 0.0
            out.append(Location(e.name, phase, t0, t1, int(r.size), rms, rms / sigma, max(excess, 0.0) / total, z,
                                z > SYSTEMATIC_Z))
        return sorted(out, key=lambda loc: -loc.excess_share)

    return build(items), build(windows)


def merge_windows(windows: Sequence[Location], sigma: float) -> list[Location]:
    """Adjacent systematic windows of one experiment merged into spans (for shading plots)."""
    spans: list[Location] = []
    for w in sorted((w for w in windows if w.systematic), key=lambda w: (w.experiment, w.t_start)):
        if spans and spans[-1].experiment == w.experiment and w.t_start - spans[-1].t_end < 2e-5 + 1e-12:
            a = spans[-1]
            n = a.n + w.n
            rms = math.sqrt((a.rms**2 * a.n + w.rms**2 * w.n) / n)
            spans[-1] = Location(a.experiment, "window", a.t_start, w.t_end, n, rms, rms / sigma,
                                 a.excess_share + w.excess_share,
                                 (a.z * math.sqrt(a.n) + w.z * math.sqrt(w.n)) / math.sqrt(n), True)
        else:
            spans.append(w)
    return spans
