"""The recording format's names (``idm-recording/1``: its id, the CSV header, the meta file)
and the error every reader raises on a recording that does not follow it, which names the
file, the line and the column."""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

PathLike = Union[str, Path]

FORMAT_ID = "idm-recording/1"
#: the exact column names of every CSV file, in order
HEADER: tuple[str, ...] = ("t", "voltage", "x")
META = "meta.json"


class RecordingError(ValueError):
    """A recording that does not follow ``idm-recording/1``.

    ``file`` is the offending file, ``line`` its 1-based line (the CSV header is line 1) and
    ``column`` the CSV column name or the ``meta.json`` key path, when they apply. The message
    starts with all three, e.g. ``exp1.csv, line 57, column 3 ('x'): not a number: 'abc'``.
    """

    def __init__(
        self,
        file: PathLike,
        message: str,
        *,
        line: Optional[int] = None,
        column: Optional[str] = None,
    ) -> None:
        self.file = Path(file)
        self.line = line
        self.column = column
        self.reason = message
        where = str(self.file)
        if line is not None:
            where += f", line {line}"
        if column is not None:
            if column in HEADER:
                where += f", column {HEADER.index(column) + 1} ('{column}')"
            else:
                where += f", key '{column}'"
        super().__init__(f"{where}: {message}")
