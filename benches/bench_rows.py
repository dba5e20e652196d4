"""The resumable benches' rows: a line of JSON per finished case in a file that shards running
side by side share, and the `--shard K/N` split of the cases between them."""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path
from typing import Any

#: the diagnosis's stages grouped as a discovery case spends them (keys of a row's ``timings``;
#: a stage not named here counts under "other")
STAGE_GROUPS: dict[str, tuple[str, ...]] = {
    "first round": ("calibration", "screening", "candidate fits", "null refits", "polish", "wider search",
                    "the structural calibrations", "held-out"),
    "second effect": ("second effect",),
    "third effect": ("third effect",),
    "discovery": ("discovery",),
    "next experiment": ("next experiment (look-alike)",),
}


def finished(path: Path) -> list[dict[str, Any]]:
    """The rows already in `path` (none when it does not exist yet)."""
    if not path.exists():
        return []
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def append(path: Path, row: dict[str, Any]) -> None:
    """One short append per case: shards side by side share the file."""
    with path.open("a") as f:
        f.write(json.dumps(row, default=str) + "\n")


def shard(spec: str) -> tuple[int, int]:
    """`--shard K/N` as (K, N): this process runs the cases whose id % N == K."""
    try:
        k, n = (int(x) for x in spec.split("/"))
        if not 0 <= k < n:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{spec!r}: expected K/N with 0 <= K < N, e.g. 0/2 and 1/2 for two processes") from None
    return k, n


def stage_shares(rows: list[dict[str, Any]]) -> str:
    """A markdown table of where the rows' seconds went (their ``timings``): each group of
    STAGE_GROUPS's share of all the seconds, and its median share per row."""
    timed = [r["timings"] for r in rows if r.get("timings")]
    if not timed:
        return ""
    named = {k for ks in STAGE_GROUPS.values() for k in ks}
    groups = {**STAGE_GROUPS, "other": ()}
    total = sum(sum(t.values()) for t in timed)
    lines = [f"| stage ({len(timed)} rows) | share of all seconds | median share per row |", "|---|---|---|"]
    for g, keys in groups.items():
        per = [sum(v for k, v in t.items() if (k in keys if keys else k not in named)) for t in timed]
        if g == "other" and not any(per):
            continue
        median = statistics.median(p / max(sum(t.values()), 1e-12) for p, t in zip(per, timed))
        lines.append(f"| {g} | {sum(per) / total:.2f} | {median:.2f} |")
    return "\n".join(lines) + "\n"
