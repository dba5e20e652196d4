"""Simulate a recorded case fast: every experiment of a case, for many parameter sets at once,
through the Rust batch engine, read out at the sensor's sample times."""

from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from ..core import engine
from ..core.batch import Structure, Tables, param_row
from ..core.batch import run as run_batch
from ..core.effects import BENCH_FIXED, oriented
from ..core.waveforms import Sawtooth
from ..io.recording import Recording
from .thresholds import FIT_DT, LATE_SNAP


@dataclass(frozen=True)
class ModelSpec:
    """One full model to simulate: structure, every parameter (normal_force None = derived), and
    the effect parameters."""

    structure: Structure
    params: Mapping[str, Optional[float]]
    effects: Mapping[str, float]


class CaseSimulator:
    """Predicts the sensor reading of every experiment of `recording` for a list of models.

    All (model, experiment) pairs of one structure go to the Rust batch in one call, so the
    Jacobian columns of a fit run in parallel (rayon, lane-interleaved RK4)."""

    def __init__(self, recording: Recording, dt: float = FIT_DT, threads: Optional[int] = None) -> None:
        self.recording = recording
        self.dt = dt
        self.threads = int(threads or os.cpu_count() or 1)
        step = recording.sample_step
        self.record_every = int(round(step / dt))
        if abs(self.record_every * dt - step) > 1e-9 * step:
            raise ValueError(f"fit step {dt} s does not divide the sample step {step} s")
        names = engine.wave_fields(Sawtooth.batch_kind)
        # sawtooth experiments share one batch; a sampled drive is its own batch (the engine's
        # sampled family shares one set of samples across its points)
        self._wave_rows = [
            None if e.is_sampled else
            [e.waveform.batch_fields()[c] for c in names]  # a Sawtooth here
            for e in recording.experiments
        ]
        #: experiments recorded with the rig turned end for end: bench-fixed effect parameters
        #: act with the other sign there (their rows and reading derivatives are negated)
        self._reversed = [e.is_reversed for e in recording.experiments]
        #: a delay between two fit steps (:meth:`late`): the sawtooth rows one step later and the
        #: weight of their run in the reading; None for none
        self._later: Optional[tuple[list[Any], float]] = None
        self.evaluations = 0  # simulated experiment runs, for reports

    def late(self, delay_s: float) -> "CaseSimulator":
        """The same simulator with every sawtooth drive felt `delay_s` [s] later than its voltage
        column says: a displacement channel read that late, simulated exactly (a shifted
        prediction interpolated between samples blurs the ringing, which a low-pass lag then fits
        better than the truth). The drive's corners must fall on fit steps, so a delay between
        two steps is run at both and the readings mixed linearly: the motion is the undelayed one
        shifted, and its interpolation over one fit step (0.2 us) is within 3e-4 of the 35 kHz
        ringing (rounded to a step instead, a 3.30 us delay run at 3.4 us left the null at chi^2
        5,698 where the mix reaches 5,642, and a sensor lag of 3.3 us fitted better). Sampled
        drives are not shifted."""
        out = copy.copy(self)
        k = engine.wave_fields(Sawtooth.batch_kind).index("delay")
        steps = delay_s / self.dt
        lo = math.floor(steps + LATE_SNAP)
        w = steps - lo
        out._wave_rows, out._later = self._shifted(k, lo * self.dt), None
        if w > LATE_SNAP:
            out._later = (self._shifted(k, (lo + 1) * self.dt), w)
        return out

    def _shifted(self, k: int, shift: float) -> list[Any]:
        """The sawtooth rows with their delay field (column k) `shift` [s] later."""
        return [None if r is None else [v + shift if i == k else v for i, v in enumerate(r)]
                for r in self._wave_rows]

    def horizon(self, j: int, cycles: Optional[int]) -> tuple[float, int]:
        """(duration [s], samples) of experiment j cut after `cycles` drive cycles (None: all)."""
        e = self.recording.experiments[j]
        if cycles is None or cycles >= e.cycles:
            return e.duration, e.n_samples
        t_end = e.rest_s + cycles / e.frequency_Hz
        return t_end, int(round(t_end * self.recording.sample_rate_Hz)) + 1

    def predict(self, specs: Sequence[ModelSpec], cycles: Optional[int] = None,
                retries: int = 2, experiments: Optional[Sequence[int]] = None) -> list[list[NDArray[np.float64]]]:
        """Readings [m] per spec, per experiment (NaN-filled where the run diverged), over the
        first `cycles` drive cycles of each experiment (None: all of it). A run that diverges is
        retried at dt/2, dt/4 ... `retries` times (a population search passes 0: a model that
        needs a smaller step is far from the data anyway, and retrying costs more than the run).
        `experiments`: only these are simulated (the others come back as empty arrays)."""
        return self._run(specs, cycles, retries, [], experiments)[0]

    def predict_checked(self, specs: Sequence[ModelSpec], cycles: Optional[int] = None
                        ) -> tuple[list[list[NDArray[np.float64]]], list[bool]]:
        """``predict``, and per spec whether every experiment's run finished at the fit step
        (no retry at a finer one, nothing diverged): its readings can then stand for the run a
        derivative request would repeat (``predict_with_sensitivities``'s `readings`)."""
        out, _, why = self._run(specs, cycles, 2, [], None)
        return out, [all(not w for w in row) and all(np.all(np.isfinite(p)) for p in r)
                     for row, r in zip(why, out)]

    def predict_with_sensitivities(self, specs: Sequence[ModelSpec], names: Sequence[str],
                                   cycles: Optional[int] = None, retries: int = 2,
                                   experiments: Optional[Sequence[int]] = None,
                                   readings: Optional[Sequence[Sequence[NDArray[np.float64]]]] = None
                                   ) -> tuple[list[list[NDArray[np.float64]]], list[list[NDArray[np.float64]]],
                                              list[list[str]]]:
        """``predict`` plus, per spec and experiment, the readings' derivatives with respect to
        ``names`` (Table 1 or effect parameters, from the engine: exact for the discrete run),
        shape (names, samples), NaN where they could not be taken, and the engine's reasons
        per spec and experiment (empty when all is well); `experiments` as for ``predict``.
        `readings`: per spec, every experiment's readings from a run of the same model that
        finished at the fit step (``predict_checked``): that run is not repeated, the engine
        takes only the derivative passes (the same numbers bit for bit), and these come back
        as the predictions."""
        return self._run(specs, cycles, retries, list(names), experiments, readings)

    def _run(self, specs: Sequence[ModelSpec], cycles: Optional[int], retries: int, names: list[str],
             experiments: Optional[Sequence[int]] = None,
             readings: Optional[Sequence[Sequence[NDArray[np.float64]]]] = None
             ) -> tuple[list[list[NDArray[np.float64]]], list[list[NDArray[np.float64]]], list[list[str]]]:
        n = len(self.recording.experiments)
        out: list[list[NDArray[np.float64]]] = [[np.zeros(0)] * n for _ in specs]
        sens: list[list[NDArray[np.float64]]] = [[np.zeros((len(names), 0))] * n for _ in specs]
        why: list[list[str]] = [[""] * n for _ in specs]
        alone = readings is not None and bool(names)  # the derivative passes alone
        extra: dict[str, Any] = {"sensitivities": names, "derivatives_only": alone} if names else {}
        by_structure: dict[Structure, list[int]] = {}
        for i, s in enumerate(specs):
            by_structure.setdefault(s.structure, []).append(i)
        n_exp = len(self.recording.experiments)
        horizons = [self.horizon(j, cycles) for j in range(n_exp)]
        enames = engine.effect_names()
        for structure, idx in by_structure.items():
            rows_p, rows_e, rows_w, t_ends = [], [], [], []
            prows = [param_row(specs[i].params) for i in idx]
            # each spec's effects row as the rig stood (False) and turned end for end (True)
            erows = {turned: [[float(oriented(specs[i].effects, turned).get(n, 0.0)) for n in enames] for i in idx]
                     for turned in (False, True)}
            wanted = range(n_exp) if experiments is None else sorted(set(experiments))
            sawtooth = [j for j in wanted if self._wave_rows[j] is not None]
            for j in wanted:
                if self._wave_rows[j] is None:
                    self._predict_sampled(j, structure, idx, prows, erows, horizons[j], retries, out, sens, why,
                                          names, derivatives_only=alone)
            if not sawtooth:
                continue
            # experiment-major: neighbouring points share a duration, so the engine's lanes of
            # points (which advance together) all stay busy to the end; a delay between two fit
            # steps runs every point at both in the same batch (:meth:`late`)
            waves = [self._wave_rows] + ([self._later[0]] if self._later is not None else [])
            for rows in waves:
                for j in sawtooth:
                    for a in range(len(idx)):
                        rows_p.append(prows[a])
                        rows_e.append(erows[self._reversed[j]][a])
                        rows_w.append(rows[j])
                        t_ends.append(horizons[j][0])
            tables = Tables(np.asarray(rows_p), np.asarray(rows_e), Sawtooth.batch_kind, np.asarray(rows_w),
                            t_ends=np.asarray(t_ends))
            res = run_batch(tables, structure, t_end=max(t_ends), method="rk4", dt=self.dt, retries=retries,
                            threads=self.threads, record_every=self.record_every, **extra)
            self.evaluations += len(t_ends)
            traces = res.get("traces", [np.zeros(0)] * len(t_ends))
            block = len(sawtooth) * len(idx)
            for a, i in enumerate(idx):
                for k, j in enumerate(sawtooth):
                    self._store(res, traces, k * len(idx) + a, horizons[j][1], i, j, out, sens, why, names)
                    if self._later is not None:
                        self._mix_later(res, traces, block + k * len(idx) + a, horizons[j][1], i, j, out, sens, why,
                                        names)
        if alone:
            assert readings is not None
            # the derivative passes alone came back without traces: the caller's readings stand
            wanted = range(n_exp) if experiments is None else sorted(set(experiments))
            for i in range(len(specs)):
                for j in wanted:
                    out[i][j] = np.asarray(readings[i][j])
        return out, sens, why

    def _mix_later(self, res: dict[str, Any], traces: Sequence[NDArray[np.float64]], point: int, samples: int,
                   i: int, j: int, out: list[list[NDArray[np.float64]]], sens: list[list[NDArray[np.float64]]],
                   why: list[list[str]], names: list[str]) -> None:
        """Spec i's experiment j read at a delay between two fit steps: the stored run (the
        earlier step) mixed with batch point `point` (the later) by the later one's weight."""
        assert self._later is not None
        w = self._later[1]
        o2: list[list[NDArray[np.float64]]] = [[]]
        s2: list[list[NDArray[np.float64]]] = [[]]
        y2: list[list[str]] = [[]]
        self._store(res, traces, point, samples, 0, j, o2, s2, y2, names)
        out[i][j] = (1.0 - w) * out[i][j] + w * o2[0][j]
        if names:
            sens[i][j] = (1.0 - w) * sens[i][j] + w * s2[0][j]
        why[i][j] = why[i][j] or y2[0][j]

    def _store(self, res: dict[str, Any], traces: Sequence[NDArray[np.float64]], point: int, samples: int, i: int,
               j: int, out: list[list[NDArray[np.float64]]], sens: list[list[NDArray[np.float64]]],
               why: list[list[str]], names: list[str]) -> None:
        """Point `point` of a batch result as spec i's experiment j (NaN where it did not run)."""
        tr = np.asarray(traces[point])
        if tr.size != samples:  # diverged or invalid point
            tr = np.full(samples, np.nan)
        for row in (out[i], sens[i], why[i]):
            self._sawtooth_slot(row, j)
        out[i][j] = tr
        why[i][j] = res["reasons"][point]
        if names:
            s = res["sensitivities"][point][:, :samples]
            sens[i][j] = s if s.shape[1] == samples else np.full((len(names), samples), np.nan)
            if self._reversed[j]:  # d reading / d theta = -(d reading / d theta) at -theta
                flip = [k for k, n in enumerate(names) if n in BENCH_FIXED]
                if flip:
                    sens[i][j] = sens[i][j].copy()
                    sens[i][j][flip] *= -1.0

    @staticmethod
    def _sawtooth_slot(row: list[Any], j: int) -> None:
        while len(row) <= j:
            row.append(None)

    def _predict_sampled(self, j: int, structure: Structure, idx: list[int], prows: list[list[float]],
                         erows: dict[bool, list[list[float]]], horizon: tuple[float, int], retries: int,
                         out: list[list[NDArray[np.float64]]], sens: list[list[NDArray[np.float64]]],
                         why: list[list[str]], names: list[str], derivatives_only: bool = False) -> None:
        """Experiment j (a sampled drive) for the specs `idx`: one batch with its samples (with
        `derivatives_only`, its derivative passes alone: see ``predict_with_sensitivities``)."""
        e = self.recording.experiments[j]
        tables = Tables(np.asarray(prows), np.asarray(erows[self._reversed[j]]), "sampled", np.ones((len(idx), 1)),
                        sampled=(np.ascontiguousarray(e.t), np.ascontiguousarray(e.voltage)),
                        t_ends=np.full(len(idx), horizon[0]))
        extra: dict[str, Any] = {"sensitivities": names, "derivatives_only": derivatives_only} if names else {}
        res = run_batch(tables, structure, t_end=horizon[0], method="rk4", dt=self.dt, retries=retries,
                        threads=self.threads, record_every=self.record_every, **extra)
        self.evaluations += len(idx)
        traces = res.get("traces", [np.zeros(0)] * len(idx))
        for a, i in enumerate(idx):
            self._store(res, traces, a, horizon[1], i, j, out, sens, why, names)
