"""Numbers, parameters and tables as the diagnosis report writes them: a value with its 1-sigma
and unit, a fitted parameter at its bound, the refitted model in one line, the calibrated and
refitted parameters' rows, a plain-text table, the words for a BIC margin."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Optional, Sequence

from ..core.declarations import structure_label
from ..core.params import PARAM_INFO
from .catalogue import CATALOGUE, by_id
from .thresholds import AT_BOUND_SHARE, BIC_THRESHOLD, CALIBRATION_RANGE

if TYPE_CHECKING:
    from typing_extensions import TypeGuard  # typing.TypeGuard from Python 3.10

    from .results import Candidate, Diagnosis

_UNITS: dict[str, str] = {ep.name: ep.unit for e in CATALOGUE for ep in e.params}
_BOUNDS: dict[str, tuple[float, float]] = {ep.name: (ep.lower, ep.upper) for e in CATALOGUE for ep in e.params}


def unit_of(name: str) -> str:
    # an effect parameter's declared unit, else Table 1's (mu_s, mu_k of a Stribeck fit)
    u = _UNITS.get(name) or (PARAM_INFO[name][1] if name in PARAM_INFO else "")
    return "" if u in ("1", "") else u


def is_finite_number(x: Optional[float]) -> TypeGuard[float]:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def pm(value: float, std: Optional[float] = None, unit: str = "") -> str:
    """``value ± std unit`` with the uncertainty's significant digits (two) and a shared power of
    ten: ``1.62e-3 ± 0.02e-3``, ``0.5338 ± 0.0002``; without a usable std, 4 significant digits."""
    u = f" {unit}" if unit else ""
    if not is_finite_number(value):
        return f"{value}{u}"
    v = float(value)
    if not is_finite_number(std) or std <= 0:
        return f"{short_number(v)}{u}"
    s = float(std)
    mag = max(abs(v), s)
    e = int(math.floor(math.log10(mag))) if mag > 0 else 0
    s_digit = int(math.floor(math.log10(s)))
    if -3 <= e <= 3:
        dec = min(max(1 - s_digit, 0), 10)
        return f"{v:.{dec}f} ± {s:.{dec}f}{u}"
    dec = min(max(e - s_digit + 1, 0), 6)
    scale = 10.0**e
    return f"{v / scale:.{dec}f}e{e} ± {s / scale:.{dec}f}e{e}{u}"


def short_number(x: float) -> str:
    """4 significant digits, exponents written short (1.24e-7)."""
    text = f"{x:.4g}"
    if "e" in text:
        m, e = text.split("e")
        text = f"{m}e{int(e)}"
    return text


def in_nm(x: float) -> str:
    return f"{x * 1e9:.2f} nm" if is_finite_number(x) else "–"


def ratio_words(x: float, sigma: float) -> str:
    return f"{x / sigma:.2f} ×" if is_finite_number(x) and sigma > 0 else "–"


def candidate_params(c: Candidate) -> list[tuple[str, float, Optional[float]]]:
    """(name, value, std) of a candidate's effect parameters, as reported (the catalogue entry
    maps a reparametrised fit back: Stribeck's excess to mu_s)."""
    out = []
    for name, v in c.params.items():
        s = c.reported_std.get(name)
        out.append((name, float(v), None if s is None else float(s)))
    return out


def at_bound(value: float, lower: float, upper: float) -> bool:
    """Whether a fitted value sits on a bound of its fit (its ±σ then means little)."""
    width = upper - lower if math.isfinite(upper - lower) else max(abs(lower), abs(upper))
    tol = AT_BOUND_SHARE * max(width, 1e-300)
    return is_finite_number(value) and (abs(value - lower) <= tol or abs(value - upper) <= tol)


def bound_note(name: str, value: float) -> str:
    b = _BOUNDS.get(name)
    return " [at bound]" if b is not None and at_bound(value, *b) else ""


def format_params(c: Candidate) -> str:
    items = candidate_params(c)
    if not items:
        return "(structure only)" if by_id(c.effect).kind == "structure" else "–"
    return ", ".join(f"{n} = {pm(v, s, unit_of(n))}{bound_note(n, v)}" for n, v, s in items)


def refit_model_line(d: Diagnosis) -> str:
    """The refitted model in one line: the nominal structure, calibrated, plus the verdict's effect."""
    nom = d.recording.nominal
    base = structure_label(nom.model, nom.n_elements)
    base += ", piezo hysteresis" if nom.piezo_hysteresis else ""
    eq = "m1 x1'' = Fpe(V, x1 - x2, x1' - x2') - Ff(x1', g, Fh)"
    cand = d.verdict_candidate
    found = getattr(d, "discovery", None)
    sec = getattr(d, "second", None)
    if sec is not None and sec.named and sec.pair is not None:
        first = by_id(sec.first.effect)
        term = f"{sec.first.effect}({first_effect_params(d)}) + {sec.pair.effect}({format_params(sec.pair)})"
        return f"{eq} + {term}   [{base}, calibrated; {first.term}; {by_id(sec.pair.effect).term}]"
    if d.verdict.endswith("discovered") and found is not None:
        return f"{eq} + [{found.equation}]   [{base}, calibrated; a library force found in the data]"
    if not d.complete:
        return "not reached (interrupted before a verdict)"
    if cand is None:
        tail = "nothing added" if d.verdict == "none" else "missing term not in the catalogue (unexplained)"
        return f"{eq}   [{base}, calibrated; {tail}]"
    term = f"{cand.effect}({format_params(cand)})" if candidate_params(cand) else cand.effect
    return f"{eq} + {term}   [{base}, calibrated; {by_id(cand.effect).term}]"


def refit_parameter_rows(d: Diagnosis) -> list[list[str]]:
    """Every fitted parameter of the verdict's refit model, as the report's table prints it:
    (parameter, meta.json, refit ±1σ, change against meta.json with [at bound] wherever the fit
    sits on a bound). Effect parameters first, then the nominal subset refitted beside them (the
    values to put in the model: they differ from the calibrated null's)."""
    cand = d.verdict_candidate
    if cand is None:
        return []
    rows: list[list[str]] = []
    spec = cand.spec
    if "+" in d.verdict and spec is not None:
        # the other named effects as refitted beside the last one (its model holds them all)
        for other in [e for e in d.verdict.split("+") if e != cand.effect]:
            for ep in by_id(other).params:
                v = spec.effects.get(ep.name, spec.params.get(ep.name))
                if v is not None:
                    rows.append([ep.name, "–", pm(float(v), None, ep.unit) + bound_note(ep.name, float(v)),
                                 "effect"])
    for name, v, sd in candidate_params(cand):
        rows.append([name, "–", pm(v, sd, unit_of(name)) + bound_note(name, v), "effect"])
    return rows + calibrated_rows(d, cand.calibrated, cand.calibrated_std)


def calibrated_rows(d: Diagnosis, values: dict[str, float], std: dict[str, float]) -> list[list[str]]:
    """(parameter, meta.json, value ±1σ, change against meta.json [at bound]) of calibrated
    nominal parameters: the calibrated null's or a refit's."""
    meta = d.recording.nominal.params.to_dict(resolved=False)
    rows = []
    for name, v in values.items():
        m = meta.get(name)
        unit = unit_of(name)
        change = f"{100 * (v / m - 1):+.2f} %" if is_finite_number(m) and m else "–"
        bound = is_finite_number(m) and at_bound(v, CALIBRATION_RANGE[0] * m, CALIBRATION_RANGE[1] * m)
        rows.append([name, short_number(m) + (f" {unit}" if unit else "") if is_finite_number(m) else "–",
                     pm(v, std.get(name), unit), change + (" [at bound]" if bound else "")])
    return rows


def first_effect_params(d: Diagnosis) -> str:
    """The first effect of a two-effect verdict with its parameters as refitted beside the second
    (they move when the second is added)."""
    sec = d.second
    assert sec is not None and sec.pair is not None and sec.pair.spec is not None
    spec = sec.pair.spec
    items = []
    for ep in by_id(sec.first.effect).params:
        v = spec.effects.get(ep.name, spec.params.get(ep.name))
        if v is not None:
            items.append(f"{ep.name} = {float(v):.4g} {ep.unit}".rstrip())
    return ", ".join(items) or "structure"


def text_table(headers: Sequence[str], rows: Sequence[Sequence[str]], align: str) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        padded = (c.ljust(w) if a == "l" else c.rjust(w) for c, w, a in zip(cells, widths, align))
        return "  " + "  ".join(padded).rstrip()

    return [line(headers), "  " + "  ".join("-" * w for w in widths)] + [line(r) for r in rows]


def evidence_words(delta_bic: float) -> str:
    """A BIC gain in words (Kass & Raftery's scale: > 10 very strong)."""
    if delta_bic >= 100:
        return "overwhelming"
    if delta_bic >= BIC_THRESHOLD:
        return "very strong"
    return "weak"
