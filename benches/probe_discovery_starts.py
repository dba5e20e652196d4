"""Probe: what each start of a discovery form's refit bought, read off the discovery bench's rows.

    python benches/probe_discovery_starts.py JSONL [JSONL ...] [--gates 1.5 2 3 5]

A found form is refitted from up to three starts of the calibrated parameters (the calibrated
values, the nominal values, where the force's own fit left them) until one leaves noise; the
rows of ``bench_discovery_structures.py`` carry every refit (``discovery_forms``,
``discovery_other_forms``: start, RMS over noise, evaluations, seconds). Per row this prints
each form's refits (a form searched globally: its local refits, then the search), and for
each gate G what a rule "the later starts only where the first
start's refit ends within G x noise" would have skipped: the seconds of the later starts, and
the forms that reached noise only from a later start while the first ended beyond G (a form
the rule would lose; it must be none); and the same for a global search run only where the
form's best local refit ended within G x noise. A probe of the evidence, not a verdict: the skipped
starts' seconds are those measured, and a lost form means the gate is wrong for that device.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

NOISE_OK = 1.1  # thresholds.NOISE_RATIO_OK: a refit at noise


def forms(row: dict[str, Any]) -> list[dict[str, Any]]:
    """Every form with its refits, on the path taken and the one before it."""
    out = []
    for key in ("discovery_other_forms", "discovery_forms"):
        out += [f for f in row.get(key, []) if f.get("starts")]
    return out


def gate(fs: list[dict[str, Any]], g: float) -> tuple[float, list[str], float, list[str]]:
    """Under gate `g`: (seconds of the later starts skipped, forms lost that way, seconds of the
    global searches skipped, forms lost that way). A global search is skipped where the form's
    best local refit ended beyond `g` x noise."""
    saved, lost, saved_wide, lost_wide = 0.0, [], 0.0, []
    for f in fs:
        local = [s for s in f["starts"] if s["start"] != "global search"]
        wide = [s for s in f["starts"] if s["start"] == "global search"]
        name = f"{f['body']}: {', '.join(f['terms'])}"
        if wide:  # its local refits are also listed as the form tried locally: counted there
            if local and min(s["rms_over_noise"] for s in local) > g:
                saved_wide += sum(s["seconds"] for s in wide)
                if f["discovered"]:
                    lost_wide.append(name)
            continue
        if len(local) < 2 or local[0]["rms_over_noise"] <= g:
            continue
        saved += sum(s["seconds"] for s in local[1:])
        if any(s["rms_over_noise"] <= NOISE_OK for s in local[1:]):
            lost.append(name)
    return saved, lost, saved_wide, lost_wide


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("jsonl", nargs="+", type=Path)
    ap.add_argument("--gates", type=float, nargs="+", default=[1.5, 2.0, 3.0, 5.0])
    a = ap.parse_args()
    rows = {}
    for p in a.jsonl:
        for line in p.read_text().splitlines():
            r = json.loads(line)
            if "verdict" in r and "discovery_forms" in r:
                rows[r["id"]] = r
    totals: dict[float, list[float]] = {g: [0.0, 0.0, 0.0, 0.0] for g in a.gates}
    print("| id | verdict | form | refits: start RMS/noise (s) |")
    print("|---|---|---|---|")
    for i, r in sorted(rows.items()):
        fs = forms(r)
        for f in fs:
            refits = "; ".join(f"{s['start']} {s['rms_over_noise']:.2f} ({s['seconds']:.0f})" for s in f["starts"])
            print(f"| {i} | {r['verdict']} | {f['body']}: {', '.join(f['terms'])} | {refits} |")
        for g in a.gates:
            saved, lost, saved_wide, lost_wide = gate(fs, g)
            t = totals[g]
            t[0], t[1], t[2], t[3] = t[0] + saved, t[1] + len(lost), t[2] + saved_wide, t[3] + len(lost_wide)
            if lost or lost_wide:
                print(f"|   | gate {g:g} would lose | {'; '.join(lost + lost_wide)} | |")
    print("\n| gate G | later starts: s skipped | forms lost | global searches: s skipped | forms lost |")
    print("|---|---|---|---|---|")
    for g, (saved, n_lost, saved_wide, n_lost_wide) in totals.items():
        print(f"| {g:g} | {saved:.0f} | {n_lost:.0f} | {saved_wide:.0f} | {n_lost_wide:.0f} |")
    print(f"\n{len(rows)} rows, {sum(r['seconds'] for r in rows.values()):.0f} s in all")


if __name__ == "__main__":
    main()
