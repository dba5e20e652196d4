"""The resumable benches' rows: a line of JSON per finished case in a file that shards running
side by side share, and the `--shard K/N` split of the cases between them."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


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
