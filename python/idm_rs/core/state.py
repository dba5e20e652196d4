"""The full state of a model at one time: what a run ends in and what another run may start
from (continue a run, or restart it mid-record)."""

from __future__ import annotations

from typing import Any, Mapping, Optional, Sequence, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import engine
from .effects import Effects
from .params import Params


class State(np.ndarray):
    """A model's state vector, with the name and unit of each component.

    A float64 array (index it, compare it, do arithmetic as with any array) that also knows its
    components: ``q0, q1, ...`` nodal displacements [m] (node 0 the main body, the last the
    weight), ``v0, v1, ...`` nodal velocities [m/s], ``g`` asperity deformation [m], ``fh``
    presliding friction force [N], ``h`` piezo hysteresis [m], then the states of effects that
    are on (``v_pe`` PE voltage [V], ``x_creep`` creep extension [m], ``x_sensor`` sensor
    reading [m]) and, with ``energy=True``, the accounting states (works [J], impulses [N s]).
    ``state["fh"]`` reads a component by name; ``t`` is the time [s] it belongs to.

    Results carry one (``SimulationResult.final_state``); build one by hand with
    :meth:`State.build` or :meth:`State.at_rest`.
    """

    components: tuple[tuple[str, str], ...]
    t: float

    def __new__(cls, values: ArrayLike, components: Sequence[tuple[str, str]], t: float = 0.0) -> "State":
        arr = np.array(values, dtype=float).ravel()
        comps = tuple((str(n), str(u)) for n, u in components)
        if arr.size != len(comps):
            raise ValueError(f"state has {arr.size} values but {len(comps)} components "
                             f"({', '.join(n for n, _ in comps)})")
        obj = arr.view(cls)
        obj.components = comps
        obj.t = float(t)
        return obj

    def __array_finalize__(self, obj: Any) -> None:
        self.components = getattr(obj, "components", ())
        self.t = getattr(obj, "t", 0.0)

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, str):
            return float(np.asarray(self)[self.index(key)])
        # a slice or a picked subset is no longer a state: plain values, no component names
        return np.asarray(self)[key]

    def __array_wrap__(self, arr: Any, context: Any = None, return_scalar: bool = False) -> Any:
        # elementwise results keep the components; reductions and reshapes become plain arrays
        if arr.shape == self.shape:
            return super().__array_wrap__(arr, context, return_scalar)
        plain = np.asarray(arr)
        return plain[()] if return_scalar else plain

    def index(self, name: str) -> int:
        """Position of component `name` in the vector."""
        for i, (n, _) in enumerate(self.components):
            if n == name:
                return i
        raise KeyError(f"no state component {name!r}; this model has {[n for n, _ in self.components]}")

    def unit(self, name: str) -> str:
        return self.components[self.index(name)][1]

    @property
    def n_nodes(self) -> int:
        return sum(1 for n, _ in self.components if n.startswith("q"))

    @property
    def nodes(self) -> NDArray[np.float64]:
        """Nodal displacements [m]."""
        return cast("NDArray[np.float64]", np.asarray(self)[: self.n_nodes].copy())

    @property
    def velocities(self) -> NDArray[np.float64]:
        """Nodal velocities [m/s]."""
        n = self.n_nodes
        return cast("NDArray[np.float64]", np.asarray(self)[n : 2 * n].copy())

    def to_dict(self) -> dict[str, float]:
        """Component name -> value (SI)."""
        return {n: float(v) for (n, _), v in zip(self.components, np.asarray(self))}

    def __repr__(self) -> str:
        if self.ndim != 1 or len(self.components) != self.size:
            return repr(np.asarray(self))
        inner = ", ".join(f"{n}={v:.6g} {u}" for (n, u), v in zip(self.components, np.asarray(self)))
        return f"State(t={self.t:g} s: {inner})"

    @classmethod
    def at_rest(cls, params: Params, *, model: str = "dps", n_elements: int = 4, piezo_hysteresis: bool = True,
                effects: Optional[Effects] = None, energy: bool = False, t: float = 0.0) -> "State":
        """Everything zero (the paper's initial condition) for this model."""
        comps = _components(params, model, n_elements, piezo_hysteresis, effects, energy)
        return cls(np.zeros(len(comps)), comps, t)

    @classmethod
    def build(cls, params: Params, values: Mapping[str, float], *, model: str = "dps", n_elements: int = 4,
              piezo_hysteresis: bool = True, effects: Optional[Effects] = None, energy: bool = False,
              t: float = 0.0) -> "State":
        """A state from named components (``{"q0": 1e-6, "v0": 0.0, "fh": 0.1, ...}``); the
        others are 0. Unknown names are refused."""
        s = cls.at_rest(params, model=model, n_elements=n_elements, piezo_hysteresis=piezo_hysteresis,
                        effects=effects, energy=energy, t=t)
        arr = np.asarray(s)
        for name, v in values.items():
            arr[s.index(name)] = float(v)
        return s


def _components(params: Params, model: str, n_elements: int, piezo_hysteresis: bool,
                effects: Optional[Effects], energy: bool) -> list[tuple[str, str]]:
    from .batch import Structure

    # ignore: any name; engine.RunConfig refuses one other than "lps", "dps" or "rig" with a ValueError
    config = Structure(model, int(n_elements), bool(piezo_hysteresis)).config()  # type: ignore[arg-type]
    return engine.state_components(params._given(), (effects or Effects()).active(), config, bool(energy))
