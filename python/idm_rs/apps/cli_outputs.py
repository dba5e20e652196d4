"""The command line's output paths, checked before a command runs: a file type it cannot write
or a place it cannot write to is refused up front, not after minutes of simulation with nothing
saved."""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path
from typing import Optional

#: what matplotlib writes without extra packages, for the figures a command draws
FIGURE_TYPES = (".png", ".pdf", ".svg")

#: per command: option -> ("file", the types it writes) or ("dir", None)
OUTPUTS: dict[str, dict[str, tuple[str, Optional[tuple[str, ...]]]]] = {
    "reproduce": {"out": ("dir", None)},
    "simulate": {"out": ("file", (".csv", ".nc")), "plot": ("file", FIGURE_TYPES)},
    "sweep": {"out": ("file", (".nc", ".zarr")), "plot": ("file", (".png",))},
    "characterize": {"out": ("dir", None)},
    "rig-fit": {"json": ("file", None), "plots": ("dir", None)},
    "diagnose": {"json": ("file", None), "plots": ("dir", None)},
}


class OutputError(ValueError):
    """An output path a command could not write to (named by its option)."""


def check_outputs(a: argparse.Namespace) -> None:
    """Refuse, naming the option, every output of command ``a.command`` that has a type the
    command does not write or lies where nothing can be written (a missing folder is created,
    as the command would)."""
    for option, (kind, types) in OUTPUTS.get(a.command, {}).items():
        value = getattr(a, option, None)
        if not value:
            continue
        path = Path(value)
        flag = f"--{option}"
        if types is not None and path.suffix.lower() not in types:
            raise OutputError(f"{flag}: unknown file type {path.suffix or '(none)'!r} in {value!r} "
                              f"(use {', '.join(types)})")
        if kind == "dir" or path.suffix.lower() == ".zarr":
            if path.exists() and not path.is_dir():
                raise OutputError(f"{flag}: {value!r} is a file, not a folder")
            folder = path if kind == "dir" else path.parent
        else:
            if path.is_dir():
                raise OutputError(f"{flag}: {value!r} is a folder; name a file")
            if path.exists() and not os.access(path, os.W_OK):
                raise OutputError(f"{flag}: cannot write {value!r} (no permission)")
            folder = path.parent
        _writable_folder(folder, flag, value)


def _writable_folder(folder: Path, flag: str, value: str) -> None:
    """Create ``folder`` if missing and prove a file can be written in it (a probe file, removed)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".idm-rs-probe-"):
            pass
    except OSError as exc:
        raise OutputError(f"{flag}: cannot write {value!r} ({exc.strerror or exc}); choose another place") from None
