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
                        ) -> tuple[list[list[NDArray[np.float64]]], list[Optional[list[float]]]]:
        """``predict``, and per spec the RK4 step [s] each experiment's run finished at (the fit
        step, or a retry's dt/2, dt/4), or None where a run diverged (or a delay's two runs
        finished at different steps): its readings can then stand for the run a derivative
        request would repeat (``predict_with_sensitivities``'s `readings` and `steps`)."""
        out, _, _, used = self._run(specs, cycles, 2, [], None)
        return out, [list(u) if all(math.isfinite(x) for x in u) and all(np.all(np.isfinite(p)) for p in r) else None
                     for u, r in zip(used, out)]

    def predict_with_sensitivities(self, specs: Sequence[ModelSpec], names: Sequence[str],
                                   cycles: Optional[int] = None, retries: int = 2,
                                   experiments: Optional[Sequence[int]] = None,
                                   readings: Optional[Sequence[Sequence[NDArray[np.float64]]]] = None,
                                   steps: Optional[Sequence[Sequence[float]]] = None
                                   ) -> tuple[list[list[NDArray[np.float64]]], list[list[NDArray[np.float64]]],
                                              list[list[str]]]:
        """``predict`` plus, per spec and experiment, the readings' derivatives with respect to
        ``names`` (Table 1 or effect parameters, from the engine: exact for the discrete run),
        shape (names, samples), NaN where they could not be taken, and the engine's reasons
        per spec and experiment (empty when all is well); `experiments` as for ``predict``.
        `readings`: per spec, every experiment's readings from a run of the same model that
        finished at the fit step (``predict_checked``): that run is not repeated, the engine
        takes only the derivative passes (the same numbers bit for bit), and these come back
        as the predictions. `steps`: with `readings`, per spec the RK4 step each experiment's run
        finished at (``predict_checked``): a run the engine had to retry at dt/2 gets its passes
        at dt/2 at once, as the retry of a full request would (the run at the fit step that
        diverged and the retried run are not repeated)."""
        return self._run(specs, cycles, retries, list(names), experiments, readings, steps)[:3]

    def _run(self, specs: Sequence[ModelSpec], cycles: Optional[int], retries: int, names: list[str],
             experiments: Optional[Sequence[int]] = None,
             readings: Optional[Sequence[Sequence[NDArray[np.float64]]]] = None,
             steps: Optional[Sequence[Sequence[float]]] = None
             ) -> tuple[list[list[NDArray[np.float64]]], list[list[NDArray[np.float64]]], list[list[str]],
                        list[list[float]]]:
        n = len(self.recording.experiments)
        out: list[list[NDArray[np.float64]]] = [[np.zeros(0)] * n for _ in specs]
        sens: list[list[NDArray[np.float64]]] = [[np.zeros((len(names), 0))] * n for _ in specs]
        why: list[list[str]] = [[""] * n for _ in specs]
        used: list[list[float]] = [[self.dt] * n for _ in specs]  # the step each run finished at [s]
        alone = readings is not None and bool(names)  # the derivative passes alone
        # the step each (spec, experiment) runs at: the fit step, or where the derivative passes
        # alone follow a run that finished at a finer one, that step
        given = steps if alone else None

        def step_of(i: int, j: int) -> float:
            return float(given[i][j]) if given is not None else self.dt

        slots = (out, sens, why, used)
        extra: dict[str, Any] = {"sensitivities": names, "derivatives_only": alone} if names else {}
        by_structure: dict[Structure, list[int]] = {}
        for i, s in enumerate(specs):
            by_structure.setdefault(s.structure, []).append(i)
        n_exp = len(self.recording.experiments)
        horizons = [self.horizon(j, cycles) for j in range(n_exp)]
        enames = engine.effect_names()
        for structure, idx in by_structure.items():
            prows = [param_row(specs[i].params) for i in idx]
            # each spec's effects row as the rig stood (False) and turned end for end (True)
            erows = {turned: [[float(oriented(specs[i].effects, turned).get(n, 0.0)) for n in enames] for i in idx]
                     for turned in (False, True)}
            wanted = range(n_exp) if experiments is None else sorted(set(experiments))
            sawtooth = [j for j in wanted if self._wave_rows[j] is not None]
            for j in wanted:
                if self._wave_rows[j] is None:
                    for dt in dict.fromkeys(step_of(i, j) for i in idx):
                        self._predict_sampled(j, structure, [a for a, i in enumerate(idx) if step_of(i, j) == dt],
                                              idx, prows, erows, horizons[j], retries, slots, names, dt,
                                              derivatives_only=alone)
            # experiment-major: neighbouring points share a duration, so the engine's lanes of
            # points (which advance together) all stay busy to the end; one batch per step (the
            # fit step, unless derivative passes alone follow retried runs)
            groups: dict[float, list[tuple[int, int]]] = {}
            for j in sawtooth:
                for a, i in enumerate(idx):
                    groups.setdefault(step_of(i, j), []).append((a, j))
            for dt, pairs in groups.items():
                self._sawtooth_batch(structure, idx, pairs, prows, erows, horizons, retries, slots, names, dt, extra)
        if alone:
            assert readings is not None
            # the derivative passes alone came back without traces: the caller's readings stand
            wanted = range(n_exp) if experiments is None else sorted(set(experiments))
            for i in range(len(specs)):
                for j in wanted:
                    out[i][j] = np.asarray(readings[i][j])
        return out, sens, why, used

    def _every(self, dt: float) -> int:
        """RK4 steps of `dt` [s] between recorded readings: a sample step's worth (a retry's
        dt/2 records every 2 x as many steps as the fit step)."""
        return self.record_every * int(round(self.dt / dt))

    def _sawtooth_batch(self, structure: Structure, idx: list[int], pairs: list[tuple[int, int]],
                        prows: list[list[float]], erows: dict[bool, list[list[float]]],
                        horizons: list[tuple[float, int]], retries: int, slots: tuple[Any, ...], names: list[str],
                        dt: float, extra: dict[str, Any]) -> None:
        """One batch of sawtooth runs, (spec `idx[a]`, experiment j) for each (a, j) of `pairs`,
        at RK4 step `dt` [s] (readings every sample step all the same), stored into `slots`
        (out, sens, why, used). A delay between two fit steps runs every point at both in the
        same batch (:meth:`late`)."""
        rows_p, rows_e, rows_w, t_ends = [], [], [], []
        waves = [self._wave_rows] + ([self._later[0]] if self._later is not None else [])
        for rows in waves:
            for a, j in pairs:
                rows_p.append(prows[a])
                rows_e.append(erows[self._reversed[j]][a])
                rows_w.append(rows[j])
                t_ends.append(horizons[j][0])
        tables = Tables(np.asarray(rows_p), np.asarray(rows_e), Sawtooth.batch_kind, np.asarray(rows_w),
                        t_ends=np.asarray(t_ends))
        res = run_batch(tables, structure, t_end=max(t_ends), method="rk4", dt=dt, retries=retries,
                        threads=self.threads, record_every=self._every(dt), **extra)
        self.evaluations += len(t_ends)
        traces = res.get("traces", [np.zeros(0)] * len(t_ends))
        for p, (a, j) in enumerate(pairs):
            self._store(res, traces, p, horizons[j][1], idx[a], j, slots, names)
            if self._later is not None:
                self._mix_later(res, traces, len(pairs) + p, horizons[j][1], idx[a], j, slots, names)

    def _mix_later(self, res: dict[str, Any], traces: Sequence[NDArray[np.float64]], point: int, samples: int,
                   i: int, j: int, slots: tuple[Any, ...], names: list[str]) -> None:
        """Spec i's experiment j read at a delay between two fit steps: the stored run (the
        earlier step) mixed with batch point `point` (the later) by the later one's weight; the
        step it finished at is NaN where the two runs finished at different steps."""
        assert self._later is not None
        out, sens, why, used = slots
        w = self._later[1]
        later: tuple[list[list[Any]], ...] = ([[]], [[]], [[]], [[]])
        self._store(res, traces, point, samples, 0, j, later, names)
        out[i][j] = (1.0 - w) * out[i][j] + w * later[0][0][j]
        if names:
            sens[i][j] = (1.0 - w) * sens[i][j] + w * later[1][0][j]
        why[i][j] = why[i][j] or later[2][0][j]
        if used[i][j] != later[3][0][j]:
            used[i][j] = math.nan

    def _store(self, res: dict[str, Any], traces: Sequence[NDArray[np.float64]], point: int, samples: int, i: int,
               j: int, slots: tuple[Any, ...], names: list[str]) -> None:
        """Point `point` of a batch result as spec i's experiment j (NaN where it did not run)
        into `slots` (out, sens, why, used: the readings, their derivatives, the engine's reason
        and the RK4 step the run finished at [s])."""
        out, sens, why, used = slots
        tr = np.asarray(traces[point])
        if tr.size != samples:  # diverged or invalid point
            tr = np.full(samples, np.nan)
        for row in (out[i], sens[i], why[i], used[i]):
            self._sawtooth_slot(row, j)
        out[i][j] = tr
        why[i][j] = res["reasons"][point]
        used[i][j] = float(res["dt_used"][point])
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

    def _predict_sampled(self, j: int, structure: Structure, members: list[int], idx: list[int],
                         prows: list[list[float]], erows: dict[bool, list[list[float]]], horizon: tuple[float, int],
                         retries: int, slots: tuple[Any, ...], names: list[str], dt: float,
                         derivatives_only: bool = False) -> None:
        """Experiment j (a sampled drive) for the specs `idx[a]`, a in `members`: one batch with its
        samples at RK4 step `dt` [s] (with `derivatives_only`, its derivative passes alone: see
        ``predict_with_sensitivities``)."""
        e = self.recording.experiments[j]
        turned = erows[self._reversed[j]]
        tables = Tables(np.asarray([prows[a] for a in members]), np.asarray([turned[a] for a in members]), "sampled",
                        np.ones((len(members), 1)),
                        sampled=(np.ascontiguousarray(e.t), np.ascontiguousarray(e.voltage)),
                        t_ends=np.full(len(members), horizon[0]))
        extra: dict[str, Any] = {"sensitivities": names, "derivatives_only": derivatives_only} if names else {}
        res = run_batch(tables, structure, t_end=horizon[0], method="rk4", dt=dt, retries=retries,
                        threads=self.threads, record_every=self._every(dt), **extra)
        self.evaluations += len(members)
        traces = res.get("traces", [np.zeros(0)] * len(members))
        for p, a in enumerate(members):
            self._store(res, traces, p, horizon[1], idx[a], j, slots, names)
