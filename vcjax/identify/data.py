"""Logged trajectories for identification: loading and checking CSV / npz logs.

A log holds, per sample k = 0..N-1, the time ``t`` [s], the vehicle's state columns (pose,
velocity, actuator states; ``FitModel.state_columns``) and the command columns applied from
sample k to k+1 (``FitModel.command_columns``); the last row's command is never used. This is
the layout of ``tests/data/remus100_pvs_reference.csv``:

* CSV (UTF-8, with or without a byte-order mark): an optional first line starting with ``#``
  (provenance, kept), then a header line of distinct column names, then one row per sample;
  extra columns are ignored.
* ``.npz``: one 1-D array per column name.

Every problem is reported before anything is compiled, as a ``ValueError`` naming the file and
the column (and the row, counting the file's lines from 1): a missing column, a non-numeric or
empty cell, NaN/inf values, a time column that does not strictly increase, fewer than 2 samples.
"""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np

__all__ = ["Log", "load_log", "save_log_csv"]


@dataclasses.dataclass(frozen=True)
class Log:
    """One logged run (float64 numpy arrays).

    Attributes:
        name: file name (for reports and figure names).
        t: (N,) sample times [s], strictly increasing.
        x: (N, n_x) measured states, columns as the model's ``state_columns``.
        u: (N, n_u) commands, columns as the model's ``command_columns``.
        provenance: the CSV's ``#`` line (without ``#``), or ``""``.
    """

    name: str
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    provenance: str = ""


def _read_csv(path: Path) -> tuple[dict[str, np.ndarray], str, int]:
    """Columns of a CSV log, its provenance line, and the file line of the first data row."""
    # utf-8-sig: a byte-order mark (as spreadsheets write) is not part of the first name
    with open(path, newline="", encoding="utf-8-sig") as f:
        lines = f.read().splitlines()
    provenance, first = "", 0
    if lines and lines[0].startswith("#"):
        provenance, first = lines[0][1:].strip(), 1
    if len(lines) <= first or not lines[first].strip():
        raise ValueError(f"{path}: no header line of column names")
    rows = list(csv.reader(lines[first:]))
    header = [h.strip() for h in rows[0]]
    seen = set()
    for j, h in enumerate(header):
        if h in seen:
            raise ValueError(
                f"{path}: column {h!r} appears twice in the header (line {first + 1}, fields "
                f"{header.index(h) + 1} and {j + 1}): which one is meant is ambiguous"
            )
        seen.add(h)
    body = [r for r in rows[1:] if any(c.strip() for c in r)]
    data = np.full((len(body), len(header)), np.nan)
    for i, row in enumerate(body):
        line_no = first + 2 + i
        if len(row) != len(header):
            raise ValueError(
                f"{path}: line {line_no} has {len(row)} fields, the header has {len(header)}"
            )
        for j, cell in enumerate(row):
            try:
                data[i, j] = float(cell)
            except ValueError:
                raise ValueError(
                    f"{path}: column {header[j]!r}, line {line_no}: not a number: {cell!r}"
                ) from None
    return {h: data[:, j] for j, h in enumerate(header)}, provenance, first + 2


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        cols = {}
        for k in z.files:
            a = np.asarray(z[k])
            if a.ndim != 1 or not np.issubdtype(a.dtype, np.number):
                raise ValueError(f"{path}: array {k!r} must be a 1-D numeric array, got {a.shape}")
            cols[k] = a.astype(np.float64)
    return cols


def load_log(path, state_columns, command_columns) -> Log:
    """Read and check one log.

    Args:
        path: ``.csv`` or ``.npz`` file.
        state_columns, command_columns: the column names the vehicle needs.

    Raises:
        ValueError: naming the file and the column (and the line) of the first problem found.
        OSError: when the file cannot be read.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    suffix = path.suffix.lower()
    provenance, line0 = "", None
    if suffix == ".csv":
        cols, provenance, line0 = _read_csv(path)
    elif suffix == ".npz":
        cols = _read_npz(path)
    else:
        raise ValueError(f"{path}: expected a .csv or .npz log, got {suffix or 'no suffix'!r}")

    need = ("t",) + tuple(state_columns) + tuple(command_columns)
    missing = [c for c in need if c not in cols]
    if missing:
        raise ValueError(
            f"{path}: missing column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(c) for c in missing)} (this vehicle's logs need {list(need)})"
        )
    lengths = {len(cols[c]) for c in need}
    if len(lengths) != 1:
        raise ValueError(f"{path}: columns have different lengths {sorted(lengths)}")

    def where(i):
        return f"line {line0 + i}" if line0 is not None else f"row {i}"

    for c in need:
        bad = np.flatnonzero(~np.isfinite(cols[c]))
        if bad.size:
            raise ValueError(
                f"{path}: column {c!r} has {bad.size} NaN/inf or empty value(s), first at "
                f"{where(int(bad[0]))}"
            )
    t = cols["t"]
    if t.size < 2:
        raise ValueError(f"{path}: needs at least 2 samples, got {t.size}")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise ValueError(
            f"{path}: column 't' must strictly increase, but t = {t[i]:g} at {where(i)} follows "
            f"t = {t[i - 1]:g}"
        )
    x = np.stack([cols[c] for c in state_columns], axis=1)
    u = np.stack([cols[c] for c in command_columns], axis=1)
    return Log(name=path.name, t=t, x=x, u=u, provenance=provenance)


def save_log_csv(path, t, x, u, state_columns, command_columns, provenance: str = "") -> Path:
    """Write a log in the CSV layout [`load_log`][vcjax.identify.data.load_log] reads (10
    significant digits)."""
    path = Path(path)
    table = np.column_stack([np.asarray(t), np.asarray(x), np.asarray(u)])
    header = ",".join(("t",) + tuple(state_columns) + tuple(command_columns))
    with open(path, "w") as f:
        if provenance:
            f.write(f"# {provenance}\n")
        f.write(header + "\n")
        np.savetxt(f, table, delimiter=",", fmt="%.10g")
    return path
