"""Measured friction data sets, loaded as rig recordings (SI units).

Three public data sets that nobody in this project made (their provenance, units and licences
are in the data folder's README; the data are never copied into the project — pass the path):

* **EMPS** (``DATA_EMPS.mat``, ``DATA_EMPS_PULSES.mat``): a ball-screw drive under a cascaded
  position loop. The drive is the reference position ``qg`` [m], the response the measured
  position ``qm`` [m]; the controller's output ``vir`` [V] times ``gtau`` [N/V] is the motor
  force; the loop gains ``kp`` [1/s] and ``kv`` [V s/m] and, in the validation run, the
  external force pulses [N] come with it.
* **Spring–slider** (ENS Lyon, ``k{K}Nm_v{V}.mat``): a 30.7 g paper slider pulled through a
  spring of stiffness K [N/m] whose far end moves at V [µm/s]. The measured response is the
  spring force (given as F / (m g)); the drive is the far end's position V t.
* **Frame** (Marino & Cicirello, ``s_b_{W}g_x.mat`` with its ``_y`` partner): a single-storey
  frame on a shaker with a brass-on-steel contact loaded by a W-gram disc; drive = base
  displacement y, response = top-plate displacement x (given in mm).

:func:`load` takes any one file of the three and returns a :class:`RigData`; a variable that is
missing, empty or holds NaN/inf samples is refused by name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import NDArray

#: slider mass of the ENS Lyon spring–slider [kg] (its README)
ENSL_SLIDER_MASS = 30.7e-3
GRAVITY = 9.81

RigKind = Literal["emps", "spring_slider", "frame"]


class RealDataError(ValueError):
    """A file that is not one of the known data sets, or one that does not read as documented."""


@dataclass(frozen=True)
class RigData:
    """One measured run of a friction rig, in SI units.

    ``drive`` is what moves the rig (a reference position, a spring end, a base) and
    ``response`` what was measured on the body; ``force`` the measured force where the data
    set has one (EMPS motor force, spring–slider spring force), else None. ``meta`` holds the
    set's constants (gains, stiffness, normal load, ...), each with its unit in the key."""

    rig: RigKind
    name: str
    t: NDArray[np.float64]  #: time [s], from 0
    drive: NDArray[np.float64]  #: [m]
    response: NDArray[np.float64]  #: [m] (EMPS, frame) or [N] (spring-slider: spring force)
    force: Union[NDArray[np.float64], None]  #: measured force [N], if any
    meta: dict[str, Any] = field(default_factory=dict)
    path: Path = Path()

    @property
    def sample_rate_Hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))


def _mat(path: Path) -> dict[str, Any]:
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        return {k: v for k, v in loadmat(str(path)).items() if not k.startswith("__")}
    except (OSError, ValueError, NotImplementedError, MatReadError) as exc:
        raise RealDataError(f"{path}: cannot read as a MATLAB file ({exc})") from None


def _column(d: dict[str, Any], key: str, path: Path) -> NDArray[np.float64]:
    """Variable ``key`` as a flat float array; refused by name when missing, empty or not finite
    (a record with NaN samples would give NaN parameters and "± nan" uncertainties)."""
    if key not in d:
        raise RealDataError(f"{path}: variable '{key}' missing (has {', '.join(sorted(d))})")
    try:
        a = np.asarray(d[key], dtype=float).ravel()
    except (TypeError, ValueError):
        raise RealDataError(f"{path}: variable '{key}' is not numeric") from None
    if a.size == 0:
        raise RealDataError(f"{path}: variable '{key}' is empty")
    bad = ~np.isfinite(a)
    if bad.any():
        raise RealDataError(f"{path}: variable '{key}' has {int(bad.sum()):,} non-finite samples (NaN or inf) of "
                            f"{a.size:,}, the first at index {int(np.flatnonzero(bad)[0])}; this record cannot be "
                            "identified (remove or repair those samples)")
    return a


def _scalar(d: dict[str, Any], key: str, path: Path) -> float:
    return float(_column(d, key, path)[0])


def load(path: Union[str, Path]) -> RigData:
    """The data set file at ``path`` (one of the three sets, recognised by its name)."""
    path = Path(path)
    if not path.exists():
        raise RealDataError(f"{path}: no such file (the data sets are not part of idm-rs; see docs/REALDATA.md)")
    name = path.name
    if re.fullmatch(r"DATA_EMPS(_PULSES)?\.mat", name):
        return load_emps(path)
    if re.fullmatch(r"k\d+Nm_v\d+\.mat", name):
        return load_spring_slider(path)
    if re.fullmatch(r"s_b_\d+g_[xy]\.mat", name):
        return load_frame(path)
    raise RealDataError(f"{path}: not a known data set file (DATA_EMPS*.mat, k<K>Nm_v<V>.mat or s_b_<W>g_x.mat)")


def load_emps(path: Path) -> RigData:
    d = _mat(path)
    t = _column(d, "t", path)
    meta: dict[str, Any] = {"kp_per_s": _scalar(d, "kp", path), "kv_V_s_per_m": _scalar(d, "kv", path),
                            "gtau_N_per_V": _scalar(d, "gtau", path), "saturation_V": 10.0}
    vir = _column(d, "vir", path)
    if "pulses_N" in d:
        meta["pulses_N"] = _column(d, "pulses_N", path)
    return RigData("emps", path.stem, t - t[0], _column(d, "qg", path), _column(d, "qm", path),
                   meta["gtau_N_per_V"] * vir, meta, path)


def load_spring_slider(path: Path) -> RigData:
    m = re.fullmatch(r"k(\d+)Nm_v(\d+)\.mat", path.name)
    assert m is not None
    k, v = float(m.group(1)), float(m.group(2)) * 1e-6
    d = _mat(path)
    t = _column(d, "t", path)
    t = t - t[0]
    force = _column(d, "Fnorm", path) * ENSL_SLIDER_MASS * GRAVITY
    meta = {"stiffness_N_per_m": k, "drive_speed_m_per_s": v, "mass_kg": ENSL_SLIDER_MASS,
            "normal_force_N": ENSL_SLIDER_MASS * GRAVITY}
    return RigData("spring_slider", path.stem, t, v * t, force, force, meta, path)


def load_frame(path: Path) -> RigData:
    m = re.fullmatch(r"s_b_(\d+)g_([xy])\.mat", path.name)
    assert m is not None
    weight_g = float(m.group(1))
    x_path = path.with_name(f"s_b_{m.group(1)}g_x.mat")
    y_path = path.with_name(f"s_b_{m.group(1)}g_y.mat")
    dx, dy = _mat(x_path), _mat(y_path)
    t = _column(dx, "t", x_path)
    if not np.array_equal(t, _column(dy, "t", y_path)):
        raise RealDataError(f"{x_path} and {y_path}: different time bases")
    meta = {"disc_mass_kg": weight_g * 1e-3, "disc_weight_N": weight_g * 1e-3 * GRAVITY}
    return RigData("frame", f"s_b_{m.group(1)}g", t - t[0], _column(dy, "y", y_path) * 1e-3,
                   _column(dx, "x", x_path) * 1e-3, None, meta, x_path)
