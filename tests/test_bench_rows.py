"""The benches' row helpers: the table of where a bench's seconds went, and the field-by-field
comparison of two diagnoses."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benches"))
from bench_diagnose_ab import differences
from bench_rows import stage_shares


def _table(text: str) -> dict[str, tuple[float, float]]:
    rows = [line.strip("|").split("|") for line in text.splitlines()[2:] if line.startswith("|")]
    return {r[0].strip(): (float(r[1]), float(r[2])) for r in rows}


def test_stage_shares_of_all_seconds_and_their_median_per_row() -> None:
    rows: list[dict[str, Any]] = [
        {"timings": {"calibration": 10.0, "wider search": 30.0, "second effect": 40.0, "discovery": 20.0}},
        {"timings": {"calibration": 50.0, "third effect": 150.0, "discovery": 100.0}},
        {"timings": {"calibration": 25.0, "discovery": 75.0, "a stage nobody grouped": 100.0}},
        {"verdict": "none"},  # a row without timings is left out
    ]
    t = _table(stage_shares(rows))
    # 600 s in all: first round 10 + 30 + 50 + 25, discovery 20 + 100 + 75
    assert t["first round"][0] == 0.19 and t["discovery"][0] == 0.33
    assert t["second effect"][0] == 0.07 and t["third effect"][0] == 0.25 and t["other"][0] == 0.17
    # per row: discovery 0.20, 0.33, 0.375 -> median 0.33; first round 0.40, 0.1667, 0.125 -> 0.17
    assert t["discovery"][1] == 0.33 and t["first round"][1] == 0.17
    assert abs(sum(share for share, _ in t.values()) - 1.0) < 0.02
    assert "| stage (3 rows)" in stage_shares(rows)


def test_no_timed_rows_no_table() -> None:
    empty: list[dict[str, Any]] = [{"verdict": "none"}, {"timings": {}}]
    assert stage_shares(empty) == ""


def test_two_diagnoses_compared_field_by_field_a_nan_equal_to_a_nan() -> None:
    a = {"verdict": "discovered", "third": {"heldout_rms": float("nan"), "rms": 1.0},
         "ranking": [{"correlation": [float("nan"), 0.5]}]}
    same = {"verdict": "discovered", "third": {"heldout_rms": float("nan"), "rms": 1.0},
            "ranking": [{"correlation": [float("nan"), 0.5]}]}
    assert differences(a, same) == []
    # a NaN against a number, a changed last digit, a missing key: each named by its path
    other = {"verdict": "discovered", "third": {"heldout_rms": 2.0, "rms": 1.0 + 2.0**-52},
             "ranking": [{"correlation": [float("nan"), 0.5]}], "extra": 1}
    assert differences(a, other) == [".extra", ".third.heldout_rms", ".third.rms"]
