"""The reference tables of the documentation, written from the declarations the engine reads
(Table 1 and the effect catalogue): every :class:`~idm_rs.Params` and :class:`~idm_rs.Effects`
field with its symbol, unit, default and meaning. ``docs/PARAMETERS.md`` is this module's output
(``python -m idm_rs.apps.reference_tables > docs/PARAMETERS.md``); a test keeps the two equal."""

from __future__ import annotations

import math

from ..core.declarations import EFFECTS, TABLE1, ParamDecl


def _unit(d: ParamDecl) -> str:
    return "–" if d.unit in ("1", "") else d.unit.replace("^2", "²").replace("^3", "³").replace("^-1", "⁻¹")


def _domain(d: ParamDecl) -> str:
    lo = "−∞" if d.lower == -math.inf else f"{d.lower:g}"
    hi = "∞" if d.upper == math.inf else f"{d.upper:g}"
    return f"{'[' if d.lower_closed else '('}{lo}, {hi})"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")  # a bar inside a cell (v2|v2|) would split it


def _value(d: ParamDecl) -> str:
    return "derived" if d.value is None else f"{d.value:g}"


def markdown() -> str:
    """Both tables as a Markdown page."""
    lines = [
        "# Parameters and effects",
        "",
        "Every field of `idm_rs.Params` (the paper's Table 1; SI units) and of `idm_rs.Effects` (the",
        "catalogue's extra physics, each off at its default), as the engine declares them. Written by",
        "`python -m idm_rs.apps.reference_tables`; set a value with `Params(mu_k=0.45)`,",
        "`Effects(k_ground=2e4)`, or `--param mu_k=0.45` / `--effect k_ground=2e4` on the command line.",
        "",
        "## `Params`",
        "",
        "| field | symbol | unit | default | valid | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for d in TABLE1:
        lines.append(f"| `{d.name}` | {d.symbol} | {_unit(d)} | {_value(d)} | {_domain(d)} | {_cell(d.meaning)} |")
    lines += [
        "",
        "`normal_force` left unset is derived: (m1 + m2 + mPE)·g, the masses as swept.",
        "",
        "## `Effects`",
        "",
        "| field | effect | symbol | unit | off at | valid | meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in EFFECTS:
        if e.kind != "term":
            continue
        for d in e.params:
            lines.append(f"| `{d.name}` | {e.id} | {d.symbol} | {_unit(d)} | {_value(d)} | {_domain(d)} | "
                         f"{_cell(d.meaning)} |")
    others = [e for e in EFFECTS if e.kind != "term"]
    if others:
        lines += ["", "The catalogue's other entries change the structure or a parameter of the paper's model "
                      "rather than adding a term:", ""]
        lines += [f"- `{e.id}` ({e.kind}): {e.physics}" for e in others]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(), end="")
