"""Shared hypothesis profiles, strategies and helpers for the idm_rs core tests.

Profiles (choose with the environment variable ``HYPOTHESIS_PROFILE``, default ``ci``):

* ``ci``  – 15 examples per property, no deadline, new random draws every run: the run's seed
  is printed at the end of pytest's report, and ``--hypothesis-seed=N`` (or the environment
  variable ``IDM_RS_HYPOTHESIS_SEED=N``) repeats exactly that run's draws;
* ``dev`` – 200 examples per property, random, for local bug hunting.

Strategies draw *physical* parameter ranges around the paper's Table 1 and short runs
(1–3 ms, dt = 1e-8 or 2e-8 s) so that one example costs well under 0.2 s. Every waveform
breakpoint is an integer multiple of 1e-5 s, so it falls on a step boundary of either dt
(``simulate`` refuses misaligned breakpoints).
"""

from __future__ import annotations

import _thread
import functools
import os
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
import pytest
from hypothesis import HealthCheck, event, note, settings
from hypothesis import strategies as st

import idm_rs

# --------------------------------------------------------------------------------------------
# hypothesis profiles
# --------------------------------------------------------------------------------------------
settings.register_profile(
    "ci",
    max_examples=15,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "dev",
    max_examples=200,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


#: the seed of this run's hypothesis draws (set in pytest_configure, printed in the summary)
_HYPOTHESIS_SEED: Optional[int] = None


def _choose_hypothesis_seed(config) -> None:
    # Every run draws new examples (a fixed set of 15 draws would test the same 15 devices
    # forever), from a seed printed at the end so that a failure in CI can be replayed exactly.
    # An explicit --hypothesis-seed is hypothesis' own option and wins.
    global _HYPOTHESIS_SEED
    from hypothesis import core

    given = config.getoption("hypothesis_seed", None)
    if given is not None:
        _HYPOTHESIS_SEED = int(given)
        return
    # a pytest-xdist worker draws from the seed its controller chose and prints
    handed = (getattr(config, "workerinput", None) or {}).get("idm_rs_hypothesis_seed")
    env = os.environ.get("IDM_RS_HYPOTHESIS_SEED")
    if handed is not None:
        _HYPOTHESIS_SEED = int(handed)
    else:
        _HYPOTHESIS_SEED = int(env) if env else int.from_bytes(os.urandom(4), "little")
    core.global_force_seed = _HYPOTHESIS_SEED


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """pytest-xdist's controller, per worker: the seed it will print goes to the worker."""
    node.workerinput["idm_rs_hypothesis_seed"] = _HYPOTHESIS_SEED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _HYPOTHESIS_SEED is not None:
        terminalreporter.write_line(
            f"hypothesis seed {_HYPOTHESIS_SEED}: repeat these draws with --hypothesis-seed={_HYPOTHESIS_SEED} "
            f"(or IDM_RS_HYPOTHESIS_SEED={_HYPOTHESIS_SEED})"
        )


def pytest_configure(config):
    _choose_hypothesis_seed(config)

    # A shell starts background jobs with SIGINT ignored, and Python then keeps it ignored: the
    # Ctrl-C tests' `_thread.interrupt_main()` would do nothing (measured: `bash -c 'pytest ... &'`
    # failed all three, in the foreground they pass). Give such a run Python's usual handler.
    import signal

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)

    # pyproject turns every warning into an error. When a hypothesis test fails, hypothesis'
    # failure report imports code that trips a third-party DeprecationWarning, and the error
    # turns the readable failure into an INTERNALERROR. Ignore exactly that warning.
    config.addinivalue_line(
        "filterwarnings", "ignore:mypy_extensions.TypedDict is deprecated:DeprecationWarning"
    )

# --------------------------------------------------------------------------------------------
# constants
# --------------------------------------------------------------------------------------------
#: grid of every waveform breakpoint [s]; a multiple of both dt values used below
TIME_GRID = 1e-5
#: the paper's d33 [m/V]
D33 = 1.24e-7
#: fastest voltage slew [V/s] for which dt = 2e-8 s is used. Above it a 2e-8 s step can leave
#: RK4's stability region in the friction state when Fs > a/(b+c): the Bouc-Wen saturation rate
#: (b+c)|dg/dt| reaches ~1e8 1/s at |v1| ~ 0.05 m/s (measured: 7 of 564 random runs at 2e-8 s
#: diverged, all with slew > 2.4e5 V/s and Fn > 14 N; 0 of 1500 with this rule).
MAX_SLEW_FOR_DT_2E8 = 2e5
#: smallest step a diverging run is retried at [s]
MIN_RETRY_DT = 2.5e-9


def grid_times(lo: float, hi: float, grid: float = TIME_GRID) -> st.SearchStrategy[float]:
    """Times in [lo, hi] [s] that are integer multiples of ``grid`` [s]."""
    return st.integers(int(round(lo / grid)), int(round(hi / grid))).map(lambda k: k * grid)


# --------------------------------------------------------------------------------------------
# parameter strategies
# --------------------------------------------------------------------------------------------
masses = st.floats(0.1, 1.0, allow_nan=False)  # m1, m2 [kg]
amplitudes = st.floats(10.0, 120.0, allow_nan=False)  # |V| [V]
rises = grid_times(0.2e-3, 1.0e-3)  # [s]
falls = grid_times(0.2e-3, 2.0e-3)  # [s]
run_lengths = grid_times(1e-3, 3e-3, grid=1e-4)  # t_end [s]
sigma2s = st.floats(0.1, 1.0, allow_nan=False)  # [N s/m]
d33s = st.floats(0.8 * D33, 1.2 * D33, allow_nan=False)  # [m/V]
rayleigh_alphas = st.floats(0.0, 1e4, allow_nan=False)  # [1/s]


@st.composite
def friction_coefficients(draw) -> tuple[float, float]:
    """(mu_k, mu_s) with 0.3 <= mu_k <= 0.6 and mu_k <= mu_s <= 0.6."""
    mu_k = draw(st.floats(0.3, 0.6, allow_nan=False))
    mu_s = draw(st.floats(mu_k, 0.6, allow_nan=False))
    return mu_k, mu_s


@st.composite
def physical_params(draw, **fixed) -> idm_rs.Params:
    """Table 1 with m1, m2, mu_k, mu_s, sigma2 and d33 drawn from physical ranges.

    Keyword arguments fix values (or, if they are strategies, draw them)."""
    mu_k, mu_s = draw(friction_coefficients())
    values = dict(
        m1=draw(masses),
        m2=draw(masses),
        mu_k=mu_k,
        mu_s=mu_s,
        sigma2=draw(sigma2s),
        d33=draw(d33s),
    )
    for name, value in fixed.items():
        values[name] = draw(value) if isinstance(value, st.SearchStrategy) else value
    return idm_rs.Params(**values)


@st.composite
def triangles(draw, signed: bool = True) -> idm_rs.Triangle:
    """A single triangular wave, |V| 10–120 V, rise 0.2–1 ms, fall 0.2–2 ms (on the 1e-5 grid)."""
    amp = draw(amplitudes)
    if signed and draw(st.booleans()):
        amp = -amp
    return idm_rs.Triangle(amplitude=amp, rise=draw(rises), fall=draw(falls))


def slew(w: idm_rs.Triangle) -> float:
    """Fastest |dV/dt| of a triangle [V/s]."""
    return abs(w.amplitude) / min(w.rise, w.fall)


@dataclass(frozen=True)
class Run:
    """Everything ``idm_rs.simulate`` needs for one short run."""

    params: idm_rs.Params
    waveform: idm_rs.Triangle
    t_end: float
    dt: float
    model: str
    n_elements: int
    piezo_hysteresis: bool = True

    def simulate(self, waveform: Optional[idm_rs.Triangle] = None, **kw) -> idm_rs.SimulationResult:
        """Run it (optionally with another waveform). A DivergenceError (a step too large for the
        friction state in fast sliding: it happens at dt = 1e-8 s for slews >~ 4e5 V/s when
        Fs > a/(b+c)) is retried at dt/2, down to 2.5e-9 s; ``result.dt`` is the step used. The
        invariants are claims about runs that return, so this does not weaken them, and the
        retry is recorded as a hypothesis event (see --hypothesis-show-statistics)."""
        kw.setdefault("save_every", 100)
        kw.setdefault("piezo_hysteresis", self.piezo_hysteresis)
        w = self.waveform if waveform is None else waveform
        dt = self.dt
        while True:
            try:
                return idm_rs.simulate(
                    self.params, w, self.t_end, dt, model=self.model, n_elements=self.n_elements, **kw
                )
            except idm_rs.DivergenceError as exc:
                if dt <= MIN_RETRY_DT:
                    raise
                event(f"DivergenceError at dt = {dt:g} s; retried at {dt / 2:g} s")
                note(f"diverged at dt = {dt:g} s ({exc.args[0]}); retrying at {dt / 2:g} s")
                dt /= 2


@st.composite
def short_runs(
    draw,
    model: Optional[str] = None,
    params: Optional[st.SearchStrategy[idm_rs.Params]] = None,
    waveform: Optional[st.SearchStrategy[idm_rs.Triangle]] = None,
    max_elements: int = 4,
) -> Run:
    """A short run (1–3 ms) of a drawn IDM; dt 2e-8 s unless the input is fast, then 1e-8 s."""
    p = draw(params if params is not None else physical_params())
    w = draw(waveform if waveform is not None else triangles())
    t_end = draw(run_lengths)
    dt = draw(st.sampled_from([1e-8, 2e-8])) if slew(w) <= MAX_SLEW_FOR_DT_2E8 else 1e-8
    m = model if model is not None else draw(st.sampled_from(["lps", "dps"]))
    n = draw(st.integers(1, max_elements)) if m == "dps" else 1
    hyst = draw(st.booleans())
    return Run(p, w, t_end, dt, m, n, hyst)


# --------------------------------------------------------------------------------------------
# physics helpers
# --------------------------------------------------------------------------------------------
def presliding_bound(p: idm_rs.Params) -> float:
    """min(Fs, a/(b+c)) [N], the bound on |Fh| (MODEL.md invariant)."""
    fs = max(p.mu_s, p.mu_k) * p.effective_normal_force
    return min(fs, p.fric_alpha / (p.fric_beta + p.fric_gamma))


def stribeck(p: idm_rs.Params, v: np.ndarray) -> np.ndarray:
    """S(v) = Fc + (Fs - Fc) exp(-(|v|/vs)^delta) [N]."""
    fn = p.effective_normal_force
    return p.mu_k * fn + (p.mu_s - p.mu_k) * fn * np.exp(-((np.abs(v) / p.stribeck_velocity) ** p.stribeck_exponent))


def asperity_rate(p: idm_rs.Params, v: np.ndarray, fh: np.ndarray) -> np.ndarray:
    """dg/dt = v - |v| sgn(Fh) |Fh / S(v)|^n [m/s] (MODEL.md eq. 6)."""
    return v - np.abs(v) * np.sign(fh) * np.abs(fh / stribeck(p, v)) ** p.fric_n


# --------------------------------------------------------------------------------------------
# the paper case (cached: several test files need the same 10 ms runs)
# --------------------------------------------------------------------------------------------
PAPER_WAVE = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3)
PAPER_T_END = 10e-3


@functools.lru_cache(maxsize=None)
def _paper_final_position(model: str, n_elements: int, dt: float, overrides: tuple) -> float:
    p = idm_rs.Params(**dict(overrides))
    r = idm_rs.simulate(p, PAPER_WAVE, PAPER_T_END, dt, model=model, n_elements=n_elements, save_every=10**7)
    return r.final_position


@pytest.fixture(scope="session")
def paper_x1() -> Callable[..., float]:
    """``paper_x1(model, n_elements=4, dt=1e-8, **param_overrides)`` -> x1(10 ms) [m] of the paper
    case (Triangle 80 V, rise 0.5 ms, fall 9.5 ms), cached for the session."""

    def run(model: str, n_elements: int = 4, dt: float = 1e-8, **overrides) -> float:
        n = n_elements if model == "dps" else 1
        return _paper_final_position(model, n, dt, tuple(sorted(overrides.items())))

    return run


# --------------------------------------------------------------------------------------------
# Ctrl-C
# --------------------------------------------------------------------------------------------
def interrupt_main_when(ready: Callable[[], bool], delay: float = 0.0, timeout: float = 300.0) -> threading.Thread:
    """Start a thread that sends Ctrl-C (``_thread.interrupt_main``) to the main thread ``delay``
    seconds [s] after ``ready()`` first holds (polled every 10 ms, for at most ``timeout`` s); the
    thread's ``sent_at`` is then the ``time.perf_counter()`` of the interrupt.
    A fixed timer is not enough: on a loaded machine it can fire before the work is under way,
    and the KeyboardInterrupt then lands outside the code that handles it."""

    def wait_then_interrupt() -> None:
        t0 = time.perf_counter()
        while not ready():
            if time.perf_counter() - t0 > timeout:
                return
            time.sleep(0.01)
        time.sleep(delay)
        thread.sent_at = time.perf_counter()  # type: ignore[attr-defined]
        _thread.interrupt_main()

    thread = threading.Thread(target=wait_then_interrupt, daemon=True)
    thread.sent_at = None  # type: ignore[attr-defined]
    thread.start()
    return thread


# --------------------------------------------------------------------------------------------
# wide strategies: every parameter the friction and hysteresis laws have, any input, effects
# --------------------------------------------------------------------------------------------
@st.composite
def wide_params(draw) -> idm_rs.Params:
    """``physical_params`` plus the friction law's shape (fric_n, the Stribeck exponent, sigma1,
    a/(b+c) on both sides of Fs), the hysteresis constants around Table 1's, and a load."""
    base = idm_rs.Params()
    return draw(physical_params(
        sigma1=st.floats(0.0, 200.0, allow_nan=False),
        fric_n=st.floats(1.0, 2.5, allow_nan=False),
        stribeck_exponent=st.floats(0.5, 2.5, allow_nan=False),
        fric_gamma=st.floats(0.1e10, 0.6e10, allow_nan=False),
        **{name: st.floats(*sorted((0.5 * getattr(base, name), 1.5 * getattr(base, name))), allow_nan=False)
           for name in ("hyst_alpha", "hyst_beta", "hyst_gamma")},
        load_force=st.floats(-0.3, 0.3, allow_nan=False),
    ))


@st.composite
def sawtooths(draw) -> idm_rs.Sawtooth:
    """A sawtooth train: |V| 10-120 V, either direction, period 0.5-3 ms, 1-3 cycles."""
    period = draw(grid_times(0.5e-3, 3e-3))
    rise = draw(grid_times(0.05e-3, period / 2))
    return idm_rs.Sawtooth(draw(amplitudes), 1.0 / period, draw(st.integers(1, 3)), rise=rise,
                           direction=draw(st.sampled_from(["forward", "backward"])))


@st.composite
def sampled_inputs(draw) -> idm_rs.Sampled:
    """A recorded-looking input: 3-8 knots on the 1e-5 s grid over 0.1-2 ms, any sign."""
    n = draw(st.integers(3, 8))
    ks = sorted(set(draw(st.lists(st.integers(1, 200), min_size=n - 1, max_size=n - 1))))
    t = np.array([0.0] + [k * TIME_GRID for k in ks])
    v = np.array([0.0] + [draw(st.floats(-120.0, 120.0, allow_nan=False)) for _ in ks])
    return idm_rs.Sampled(t, v)


def any_input() -> st.SearchStrategy:
    """A triangle, a sawtooth train or a sampled input."""
    return st.one_of(triangles(), sawtooths(), sampled_inputs())


#: each catalogue effect with a physical range of its parameter(s)
EFFECT_RANGES: dict[str, tuple[float, float]] = {
    "tau_amp": (1e-6, 2e-5), "tau_sensor": (1e-6, 5e-5), "k_ground": (1e2, 1e4), "c_weight": (0.05, 2.0),
    "theta_rad": (-0.05, 0.05), "drift_rate": (-1e-5, 1e-5), "eps": (-0.1, 0.1),
}


@st.composite
def some_effects(draw, exclude: tuple[str, ...] = ()) -> idm_rs.Effects:
    """Up to three catalogue effects on at once (creep as its pair kappa, tau_creep)."""
    names = sorted(set(EFFECT_RANGES) - set(exclude)) + ([] if "kappa" in exclude else ["creep"])
    chosen = draw(st.lists(st.sampled_from(names), max_size=3, unique=True))
    values: dict[str, float] = {}
    for name in chosen:
        if name == "creep":
            values["kappa"] = draw(st.floats(0.002, 0.05, allow_nan=False))
            values["tau_creep"] = draw(st.floats(1e-4, 5e-3, allow_nan=False))
        else:
            values[name] = draw(st.floats(*EFFECT_RANGES[name], allow_nan=False))
    return idm_rs.Effects(**values)


def fastest_slew(w) -> float:
    """Fastest |dV/dt| of any piecewise-linear input [V/s]."""
    t, v = w.breakpoints()
    d = np.diff(np.asarray(t, dtype=float))
    return float(np.max(np.abs(np.diff(np.asarray(v, dtype=float))[d > 0] / d[d > 0]), initial=0.0))


@pytest.fixture
def saved(monkeypatch):
    """Every matplotlib figure saved while the test runs (the figure objects, to inspect)."""
    from matplotlib.figure import Figure

    figs = []
    real = Figure.savefig

    def keep(self, *args, **kwargs):
        out = real(self, *args, **kwargs)
        figs.append(self)
        return out

    monkeypatch.setattr(Figure, "savefig", keep)
    return figs
