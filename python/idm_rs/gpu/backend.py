"""Packing sweep points for the kernel, and running it on a GPU (CuPy, NVRTC) or on the CPU (the
same source compiled by the system C compiler, loaded with ctypes).

The kernel is specialised at compile time (``Spec``: the right-hand side and state layout the
engine generates from its model for the points' shape, ``engine.kernel_program``), so its state
lives in registers. Its inputs are columns: the per-point constants of each distinct parameter
row (packed by the engine in the order the generated code reads them), indexed per point by
``rows``, and the wave's six numbers per point; a column equal over the whole batch is sent once
(step 0)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal

import numpy as np
from numpy.typing import NDArray

from ..core import engine

SOURCE = Path(__file__).with_name("idm_kernel.cu")
#: outputs per point, in the kernel's order
OUTPUTS = ("final_position", "peak_velocity", "peak_friction", "slip_fraction", "status", "diverged_at")
#: the adaptive kernel's outputs after those: accepted steps, smallest step, crawled (1/0)
ADAPTIVE_EXTRA = 3
#: CUDA threads per block (the LPS; see Spec.block)
BLOCK = 128
#: NVRTC options, as the CUDA backend compiles (CuPy adds the architecture)
NVRTC_OPTIONS = ("--std=c++14",)
#: kernel entry points by method
ENTRY = {"rk4": "idm_rk4_sweep", "dopri5": "idm_dopri5_sweep"}


class GpuUnavailable(RuntimeError):
    """No usable GPU backend here (CuPy missing, no device, or no C compiler for the CPU build)."""


@dataclass(frozen=True)
class Spec:
    """A compile-time specialisation of the kernel: the generated ``layout`` (``#define``s: node
    count, state size, error scales, the constants row) and right-hand side ``rhs`` (the C
    function ``idm_rhs``), both from ``engine.kernel_program`` for one shape of model."""

    layout: str
    rhs: str

    def _layout_number(self, name: str) -> int:
        """The generated layout's ``#define name N``."""
        return int(re.search(rf"#define {name} (\d+)", self.layout).group(1))  # type: ignore[union-attr]

    @property
    def nodes(self) -> int:
        """Number of nodes (2 for the LPS, n + 1 for the DPS with n elements)."""
        return self._layout_number("IDM_N")

    @property
    def dim(self) -> int:
        """Numbers in the state (positions, velocities, friction, hysteresis, the effects' own)."""
        return self._layout_number("IDM_DIM")

    @property
    def block(self) -> int:
        """Threads per CUDA block: 64 where the middle stages live in shared memory (DPS), 32 from
        a state of 15 numbers on (ptxas for sm_90 gave the DPS 5 with hysteresis, 15 numbers, 254
        registers and an 8-byte spill in blocks of 64, 170 registers and none in blocks of 32:
        same code, a smaller launch bound; and the stage output of ``shared_stages`` 2 fits the
        48 KB of static shared memory only so)."""
        return BLOCK if self.nodes == 2 else 64 if self.dim < 15 else 32

    @property
    def shared_stages(self) -> int:
        """Where the Dormand-Prince stages live: 0 in registers (the LPS); 1 the middle stages
        k2..k7 in shared memory (the DPS: in registers they spilled from 3 nodes on); 2 the
        stage's output too, from a state of 16 numbers on (the DPS 4 with every effect on: 254
        registers and an 8-byte spill for sm_90 at 1, 252 registers and none at 2)."""
        return 0 if self.nodes == 2 else 1 if self.dim < 16 else 2

    def defines(self) -> str:
        """The compile-time constants besides the layout: the block and where the stages live.
        The wave's numbers and the step loop's metrics stay in registers (IDM_WAVE_SHARED and
        IDM_METRICS_SHARED 0: with the generated right-hand side the LPS's RK4 needs 124
        registers without them, and with them ptxas spilled 8 bytes for sm_90)."""
        return (f"#define IDM_BLOCK {self.block}\n#define IDM_SHARED_STAGES {self.shared_stages}\n"
                "#define IDM_WAVE_SHARED 0\n#define IDM_METRICS_SHARED 0\n")


def program(config: Any, param_rows: NDArray[np.float64],
            effect_rows: NDArray[np.float64]) -> tuple[Spec, NDArray[np.float64]]:
    """The kernel's specialisation for points of one shape and each row's constants: the engine
    traces its model of the first row and refuses, naming the row, what the kernel cannot run."""
    layout, rhs, consts = engine.kernel_program(config, np.ascontiguousarray(param_rows, dtype=float),
                                                np.ascontiguousarray(effect_rows, dtype=float))
    return Spec(layout, rhs), np.ascontiguousarray(consts)


def spec_of(model: Literal["lps", "dps"] = "lps", n_elements: int = 1, piezo_hysteresis: bool = True,
            effects: Any = None) -> Spec:
    """The specialisation for one structure and set of effects (``Effects``; none by default) at
    Table 1's values (the shape, not the values, decides it)."""
    from ..core.batch import Structure, param_row
    from ..core.effects import Effects
    from ..core.params import Params

    config = Structure(model, n_elements, piezo_hysteresis).config(method="rk4", dt=1e-8)
    e = effects or Effects()
    row = np.array([[getattr(e, name) for name in engine.effect_names()]], dtype=float)
    return program(config, np.asarray([param_row(Params())], dtype=float), row)[0]


def all_specs() -> list[Spec]:
    """The specialisations the NVRTC test compiles: every node count with and without piezo
    hysteresis and no effect, and the LPS, the DPS 4 and the largest DPS with every catalogue
    effect on at once (the largest right-hand sides and states)."""
    from ..core.effects import Effects

    max_dof = engine.kernel_accepts()["max_dof"]
    specs = [spec_of("lps" if n == 2 else "dps", max(n - 1, 1), h)
             for n in range(2, max_dof + 1) for h in (True, False)]
    # every effect parameter on (1e-3 in SI: in every domain; its size does not change the code)
    every = Effects(**{name: 1e-3 for name in engine.effect_names()})
    largest: list[tuple[Literal["lps", "dps"], int]] = [("lps", 1), ("dps", 4), ("dps", max_dof - 1)]
    specs += [spec_of(m, k, True, every) for m, k in largest]
    return specs


@dataclass
class KernelBatch:
    """The kernel's inputs for P points: ``consts`` (R, IDM_NC) one row per distinct parameter
    row, ``rows`` (P,) each point's row; the wave's six columns in ``data``: column k of point p
    is ``data[off[k] + step[k] * p]`` (step 0: one value for all). ``method`` "rk4" uses ``dt``
    and ``steps``; "dopri5" uses ``t_end``, ``rtol``, ``atol`` and ``first_step``."""

    spec: Spec
    consts: NDArray[np.float64]
    rows: NDArray[np.int32]
    data: NDArray[np.float64]
    off: NDArray[np.int64]
    step: NDArray[np.int64]
    dt: float
    steps: int
    method: str = "rk4"
    t_end: float = 0.0
    rtol: float = 1e-7
    atol: float = 1e-7
    first_step: float = 1e-8

    @property
    def points(self) -> int:
        return int(self.rows.size)


def wave_columns(kind: str, fields: dict[str, Any]) -> list[Any]:
    """The kernel's six wave columns (delay [s], amplitude [V], peak time in a cycle [s], span
    [s]: fall or period, cycles, 1 for a Triangle) from the family's batch fields (scalars or
    per-point arrays): the arithmetic of waveforms.py."""
    f = {k: np.asarray(v, dtype=float) for k, v in fields.items()}
    if kind == "triangle":
        return [f["delay"], f["amplitude"], f["rise"], f["fall"], np.float64(1.0), np.float64(1.0)]
    period = 1.0 / f["frequency"]
    peak = np.where(f["forward"] != 0.0, f["rise"], period - f["rise"])
    return [f["delay"], f["amplitude"], peak, period, f["cycles"], np.float64(0.0)]


def _columns(values: list[Any], points: int) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """The columns packed one after another, each once where it is uniform (step 0), else
    whole (step 1, ``points`` values): (data, off, step)."""
    cols, steps = [], []
    for v in values:
        v = np.atleast_1d(np.asarray(v, dtype=float))
        if v.size == 1 or (v == v[0]).all():
            cols.append(v[:1])
            steps.append(0)
        else:
            if v.size != points:
                raise ValueError(f"a wave column has {v.size} values for {points} points")
            cols.append(v)
            steps.append(1)
    sizes = np.array([c.size for c in cols])
    off = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    return np.concatenate(cols), off, np.asarray(steps, dtype=np.int64)


def pack(config: Any, param_rows: NDArray[np.float64], effect_rows: NDArray[np.float64], rows: NDArray[np.integer],
         wave: list[Any], t_end: float, dt: float, *, method: str = "rk4", rtol: float = 1e-7,
         atol: float = 1e-7, first_step: float = 1e-8) -> KernelBatch:
    """The kernel's inputs: the specialisation and constants of the distinct parameter rows
    (``param_rows`` (R, len(param_names())), ``effect_rows`` (R, len(effect_names())); the engine
    refuses what the kernel cannot run), ``rows`` (P,) the row of each point, ``wave`` the six
    wave columns (scalars or (P,) arrays: ``wave_columns``)."""
    spec, consts = program(config, param_rows, effect_rows)
    rows32 = np.ascontiguousarray(rows, dtype=np.int32)
    data, off, step = _columns(list(wave), rows32.size)
    return KernelBatch(spec, consts, rows32, data, off, step, float(dt), int(round(t_end / dt)), method,
                       float(t_end), float(rtol), float(atol), float(first_step))


def prepare(config: Any, params_table: NDArray[np.float64], waves: tuple[str, dict[str, Any]], t_end: float,
            dt: float, *, effects_table: Any = None, method: str = "rk4", rtol: float = 1e-7, atol: float = 1e-7,
            first_step: float = 1e-8) -> KernelBatch:
    """One row of ``params_table`` (and of ``effects_table``; none by default) per point, with its
    wave as (family, batch fields: scalars or per-point arrays). For tests and small batches;
    the sweep packs with ``pack`` (one row per distinct parameter row)."""
    p = np.asarray(params_table).shape[0]
    if effects_table is None:
        effects_table = np.zeros((p, len(engine.effect_names())))
    return pack(config, params_table, effects_table, np.arange(p), wave_columns(*waves), t_end, dt, method=method,
                rtol=rtol, atol=atol, first_step=first_step)


#: where the generated right-hand side goes in the kernel source
RHS_MARKER = "IDM_GENERATED_RHS"


def kernel_source(spec: Spec) -> str:
    """The kernel as compiled: the engine's shared header (crawl limits, tableaus), the generated
    layout and the specialisation in front of ``idm_kernel.cu``, the generated right-hand side in
    place of its marker."""
    source = SOURCE.read_text()
    if source.count(RHS_MARKER) != 1:
        raise GpuUnavailable(f"kernel source ({SOURCE}) has no place for the generated right-hand side: "
                             "reinstall idm-rs")
    return engine.kernel_header() + spec.layout + spec.defines() + source.replace(RHS_MARKER, spec.rhs)


def _outputs(raw: NDArray[np.float64]) -> dict[str, NDArray[Any]]:
    """The kernel's output columns (rows of ``raw``) by name."""
    out = {name: raw[i] for i, name in enumerate(OUTPUTS)}
    out["status"] = out["status"].astype(np.uint8)
    out["diverged_at"] = np.where(out["status"] == 3, out["diverged_at"], np.nan)
    if raw.shape[0] > len(OUTPUTS):  # the adaptive kernel: accepted steps, smallest step, crawled
        out["steps"] = raw[6].astype(np.uint64)
        out["dt_used"] = raw[7]
        out["crawled"] = raw[8] == 1.0
    return out


def _n_outputs(method: str) -> int:
    return len(OUTPUTS) + (ADAPTIVE_EXTRA if method == "dopri5" else 0)


# --- the CPU build --------------------------------------------------------------------------------

_CPU_LIBS: dict[Spec, ctypes.CDLL] = {}


def _cpu_library(spec: Spec) -> ctypes.CDLL:
    if spec in _CPU_LIBS:
        return _CPU_LIBS[spec]
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise GpuUnavailable("no C compiler (cc) to build the kernel for the CPU")
    source = kernel_source(spec)
    tag = hashlib.sha256(source.encode()).hexdigest()[:16]
    lib = Path(tempfile.gettempdir()) / f"idm_kernel_cpu_{tag}.so"
    if not lib.exists():
        tmp = lib.with_suffix(f".{os.getpid()}.so")
        cmd = [cc, "-O2", "-std=c99", "-shared", "-fPIC", "-x", "c", "-", "-o", str(tmp), "-lm"]
        r = subprocess.run(cmd, input=source, capture_output=True, text=True)
        if r.returncode != 0:
            raise GpuUnavailable(f"building the kernel for the CPU failed: {r.stderr.strip()[:500]}")
        os.replace(tmp, lib)
    dll = ctypes.CDLL(str(lib))
    dp, lp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_longlong), ctypes.POINTER(ctypes.c_int)
    d, ll = ctypes.c_double, ctypes.c_longlong
    dll.idm_rk4_sweep.argtypes = [dp, ip, dp, lp, lp, d, ll, ll, ll, dp]
    dll.idm_rk4_sweep.restype = None
    dll.idm_dopri5_sweep.argtypes = [dp, ip, dp, lp, lp, d, d, d, d, ll, ll, dp]
    dll.idm_dopri5_sweep.restype = None
    _CPU_LIBS[spec] = dll
    return dll


def run_cpu(batch: KernelBatch) -> dict[str, NDArray[Any]]:
    """The kernel compiled for the CPU (one point after another): the reference the tests hold
    the GPU source to."""
    dll = _cpu_library(batch.spec)
    ptr: Callable[[NDArray[Any], Any], Any] = lambda a, t: a.ctypes.data_as(ctypes.POINTER(t))  # noqa: E731
    data = np.ascontiguousarray(batch.data)
    common = (ptr(batch.consts, ctypes.c_double), ptr(batch.rows, ctypes.c_int), ptr(data, ctypes.c_double),
              ptr(batch.off, ctypes.c_longlong), ptr(batch.step, ctypes.c_longlong))
    out = np.zeros((_n_outputs(batch.method), batch.points))
    if batch.method == "dopri5":
        dll.idm_dopri5_sweep(*common, batch.t_end, batch.rtol, batch.atol, batch.first_step, 0, batch.points,
                             ptr(out, ctypes.c_double))
    else:
        dll.idm_rk4_sweep(*common, batch.dt, batch.steps, 0, batch.points, ptr(out, ctypes.c_double))
    return _outputs(out)


# --- the GPU --------------------------------------------------------------------------------------

_MODULES: dict[Spec, Any] = {}


def _cupy() -> Any:
    try:
        import cupy as cp
    except ImportError:
        raise GpuUnavailable("backend='cuda' needs CuPy and an NVIDIA GPU: pip install 'idm-rs[cuda]'") from None
    try:
        if cp.cuda.runtime.getDeviceCount() < 1:
            raise GpuUnavailable("backend='cuda': no CUDA device found")
    except cp.cuda.runtime.CUDARuntimeError as exc:
        raise GpuUnavailable(f"backend='cuda': no usable CUDA device ({exc})") from None
    return cp


class Finished:
    """A block already run (the CPU build): ``result()`` returns its outputs."""

    def __init__(self, res: dict[str, NDArray[Any]]) -> None:
        self._res = res

    def done(self) -> bool:
        return True

    def result(self) -> dict[str, NDArray[Any]]:
        return self._res


class Launched:
    """A block running on the GPU: ``result()`` waits for it and brings its outputs back."""

    def __init__(self, out: Any, stream: Any, events: tuple[Any, Any]) -> None:
        self._out, self._stream, self._events = out, stream, events
        #: the kernel's own time [s] (CUDA events around the launch), known after result()
        self.kernel_s = float("nan")

    def done(self) -> bool:
        """Whether the GPU has finished the block (without waiting)."""
        return bool(self._stream.done)

    def result(self) -> dict[str, NDArray[Any]]:
        import cupy as cp

        self._stream.synchronize()
        self.kernel_s = cp.cuda.get_elapsed_time(*self._events) / 1e3
        return _outputs(self._out.get(stream=self._stream))


def launch_cuda(batch: KernelBatch) -> Launched:
    """Start the kernel on the GPU on its own stream and return at once (the host packs the
    next block meanwhile): one thread per point, in grid order (neighbouring points share a
    warp), blocks of ``BLOCK`` threads."""
    cp = _cupy()
    spec = batch.spec
    if spec not in _MODULES:
        _MODULES[spec] = cp.RawModule(code=kernel_source(spec), options=NVRTC_OPTIONS)
    stream = cp.cuda.Stream(non_blocking=True)
    with stream:
        d = {name: cp.asarray(getattr(batch, name)) for name in ("consts", "rows", "data", "off", "step")}
        out = cp.empty((_n_outputs(batch.method), batch.points), dtype=cp.float64)
        grid = ((batch.points + spec.block - 1) // spec.block,)
        common = (d["consts"], d["rows"], d["data"], d["off"], d["step"])
        f = _MODULES[spec].get_function(ENTRY[batch.method])
        if batch.method == "dopri5":
            args: tuple[Any, ...] = common + (np.float64(batch.t_end), np.float64(batch.rtol),
                                              np.float64(batch.atol), np.float64(batch.first_step), np.int64(0),
                                              np.int64(batch.points), out)
        else:
            args = common + (np.float64(batch.dt), np.int64(batch.steps), np.int64(0), np.int64(batch.points), out)
        start, end = cp.cuda.Event(), cp.cuda.Event()
        start.record(stream)
        f(grid, (spec.block,), args)
        end.record(stream)
    return Launched(out, stream, (start, end))


def run_cuda(batch: KernelBatch) -> dict[str, NDArray[Any]]:
    """The kernel on the GPU, waited for."""
    return launch_cuda(batch).result()
