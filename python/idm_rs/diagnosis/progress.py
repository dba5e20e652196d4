"""The progress bar of a diagnosis (a share of the bar per stage, an ETA from the whole run's rate)
and the clock that times the stages."""

from __future__ import annotations

import time
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Callable, Iterator, Optional

#: the clock of the diagnosis running in this context, and the names of the parts open in it
_CLOCK: ContextVar[Optional["Clock"]] = ContextVar("idm_rs_diagnosis_clock", default=None)
_OPEN: ContextVar[tuple[str, ...]] = ContextVar("idm_rs_diagnosis_parts", default=())


class Clock:
    """Seconds per stage; a stage run twice (held-out) sums. Tells the progress bar, if any,
    that the stage is done. Within stages, :func:`part` adds the seconds, simulations and calls
    of named parts to ``parts`` (a part inside another is named after both, "a / b", and is
    counted in both)."""

    def __init__(self, progress: Optional["Progress"] = None,
                 evaluations: Optional[Callable[[], int]] = None) -> None:
        self.timings: dict[str, float] = {}
        #: part name -> [seconds, simulated runs, calls]
        self.parts: dict[str, list[float]] = {}
        self._last = time.perf_counter()
        self._progress = progress
        self._evaluations = evaluations

    def restart(self) -> None:
        """The next stage is timed from now (what ran before it is not a stage)."""
        self._last = time.perf_counter()

    @contextmanager
    def active(self) -> Iterator["Clock"]:
        """This clock receives the parts timed in the block (and in what it calls)."""
        token = _CLOCK.set(self)
        try:
            yield self
        finally:
            _CLOCK.reset(token)

    def begin(self, name: str) -> None:
        """An optional stage starts: the progress bar, if any, grows by its share."""
        if self._progress is not None:
            self._progress.stage_begins(name)

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timings[name] = self.timings.get(name, 0.0) + now - self._last
        self._last = now
        if self._progress is not None:
            self._progress.stage_done(name)


@contextmanager
def part(name: str) -> Iterator[None]:
    """Times a named part of a stage on the active clock (none: nothing is timed): its seconds,
    the simulated runs it made and how often it ran, under the names of the parts it is in."""
    clock = _CLOCK.get()
    if clock is None:
        yield
        return
    full = _OPEN.get() + (name,)
    token = _OPEN.set(full)
    runs = clock._evaluations
    t0, n0 = time.perf_counter(), runs() if runs is not None else 0
    try:
        yield
    finally:
        _OPEN.reset(token)
        row = clock.parts.setdefault(" / ".join(full), [0.0, 0.0, 0.0])
        row[0] += time.perf_counter() - t0
        row[1] += (runs() if runs is not None else 0) - n0
        row[2] += 1


#: the diagnosis's stages: (name, share of a typical run's time [%], typical simulations), from
#: the dev-set timings (benches/RESULTS.md); the progress bar advances by stage with an ETA
STAGES: tuple[tuple[str, float, float], ...] = (
    ("calibration", 40.0, 1500.0),
    ("screening", 6.0, 30.0),
    ("candidate fits", 34.0, 300.0),
    ("null refits", 6.0, 30.0),
    ("polish", 6.0, 30.0),
    ("wider search", 4.0, 300.0),
    ("held-out", 4.0, 10.0),
    # the stages that run only on some cases (a first effect leaving a systematic residual, an
    # unexplained residual, an alternative or an undetermined parameter): no share of the bar
    # until they start; one that starts lengthens the bar by OPTIONAL_SHARE (it can take longer
    # than everything before it, and a bar at 100 % for minutes says the run is over)
    ("second effect", 0.0, 300.0),
    ("third effect", 0.0, 300.0),
    ("discovery", 0.0, 100.0),
    ("next experiment", 0.0, 50.0),
    ("next experiment (look-alike)", 0.0, 50.0),
    ("next experiment (parameter)", 0.0, 50.0),
)

#: how much longer a run gets when an optional stage starts [% of the first stages' 100]
OPTIONAL_SHARE: dict[str, float] = {
    "second effect": 60.0, "third effect": 60.0, "discovery": 80.0, "next experiment": 10.0,
    "next experiment (look-alike)": 10.0, "next experiment (parameter)": 10.0,
}


class Progress:
    """A percent bar over the stages: each stage owns its share, simulations advance it within the
    stage (approaching the share's end, as a stage's length is not known in advance). The ETA is
    the average rate of the whole run so far (tqdm's smoothing 0), not the last few updates':
    a stage that runs long no longer sends it from minutes to an hour and back. Beside it: the
    stage and the simulated runs, counted as the report counts them (``runs()``, the
    simulator's own count, one per experiment simulated)."""

    def __init__(self, name: str, runs: Optional[Callable[[], int]] = None) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=100.0, desc=f"diagnosing {name}", unit="%", smoothing=0.0,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]")
        self.stage, self.start, self.in_stage, self.evals = 0, 0.0, 0.0, 0
        self.started: set[str] = set()  # the optional stages that ran
        self.runs = runs
        self._show()

    def _show(self) -> None:
        name = STAGES[self.stage][0] if self.stage < len(STAGES) else "done"
        count = self.runs() if self.runs is not None else self.evals
        self.bar.set_postfix_str(f"{name}, {count} simulated runs", refresh=False)

    def _share(self, index: int) -> float:
        stage, share, _ = STAGES[index]
        return OPTIONAL_SHARE.get(stage, 0.0) if stage in self.started else share

    def update(self, n: int = 1) -> None:
        """``n`` more simulations."""
        self.evals += int(n)
        if self.stage < len(STAGES):
            _, _, typical = STAGES[self.stage]
            self.in_stage += n
            target = self.start + self._share(self.stage) * (1.0 - 0.5 ** (self.in_stage / typical))
            self.bar.update(max(0.0, target - self.bar.n))
        self._show()

    def stage_begins(self, name: str) -> None:
        """An optional stage starts (``Clock.begin``): the stages before it are passed over and
        the bar lengthens by its OPTIONAL_SHARE (the percentage drops: the run has grown)."""
        names = [st[0] for st in STAGES]
        if name not in names or names.index(name) < self.stage:
            return
        while self.stage < names.index(name):
            self.start += self._share(self.stage)
            self.stage += 1
        if name not in self.started:
            self.started.add(name)
            self.bar.total += OPTIONAL_SHARE.get(name, 0.0)
        self.in_stage = 0.0
        self.bar.update(max(0.0, self.start - self.bar.n))
        self.bar.refresh()
        self._show()

    def stage_done(self, name: str) -> None:
        while self.stage < len(STAGES):
            stage = STAGES[self.stage][0]
            self.start += self._share(self.stage)
            self.stage += 1
            if stage == name:
                break
        self.in_stage = 0.0
        self.bar.update(max(0.0, self.start - self.bar.n))
        self._show()

    def close(self, done: bool = True) -> None:
        if done:
            self.bar.update(max(0.0, self.bar.total - self.bar.n))
        self.bar.close()


def progress_bar(show: bool, name: str, runs: Optional[Callable[[], int]] = None) -> Optional[Progress]:
    return Progress(name, runs) if show else None
