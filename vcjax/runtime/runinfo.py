"""``run.json``: what every output folder records about the run that wrote it.

Enough to reproduce the run: the command line, the configuration as parsed (after defaults and
validation), the seeds, the vcjax version and git commit (with a flag for uncommitted changes),
the Python, jax, jaxlib, numpy versions, the float precision, the devices and processes, and
wall times. [`run_info`][vcjax.runtime.runinfo.run_info] collects it,
[`write_run_json`][vcjax.runtime.runinfo.write_run_json] writes it (in a multi-process
run, only process 0 writes).
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import math
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

import jax
import numpy as np

__all__ = ["run_info", "write_run_json", "to_jsonable", "git_commit"]

#: the checkout's root when vcjax runs from one (``vcjax/runtime/runinfo.py`` two folders down)
_REPO = Path(__file__).resolve().parents[2]


def git_commit(path: Path = _REPO) -> dict | None:
    """``{"commit": sha, "dirty": bool}`` of the git checkout whose root is ``path``, or None
    (not a checkout's root, e.g. an installed wheel inside some other repository, or git
    missing)."""
    try:
        top = subprocess.run(
            ["git", "-C", str(path), "rev-parse", "--show-toplevel"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        if top.returncode != 0 or Path(top.stdout.strip()).resolve() != Path(path).resolve():
            return None
        sha = subprocess.run(
            ["git", "-C", str(path), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        if sha.returncode != 0:
            return None
        st = subprocess.run(
            ["git", "-C", str(path), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": sha.stdout.strip(), "dirty": bool(st.stdout.strip())}


def to_jsonable(x: Any) -> Any:
    """Plain-JSON form of a config value: dicts, lists, numbers, strings; paths and enums as
    strings, NumPy/JAX arrays as (nested) lists, dataclasses and NamedTuples as dicts,
    non-finite floats as strings ("inf", "nan")."""
    if isinstance(x, dict):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: to_jsonable(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, tuple) and hasattr(x, "_asdict"):
        return {k: to_jsonable(v) for k, v in x._asdict().items()}
    if isinstance(x, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in x]
    if isinstance(x, Path | enum.Enum):
        return str(x.value if isinstance(x, enum.Enum) else x)
    if isinstance(x, bool | str) or x is None:
        return x
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else str(float(x))
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return to_jsonable(np.asarray(x).tolist())
    if callable(x):
        return getattr(x, "__qualname__", repr(x))
    return repr(x)


def _version(name: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def run_info(
    command: str,
    config: Any = None,
    seeds: dict | None = None,
    wall_s: dict | float | None = None,
    argv: list[str] | None = None,
    extra: dict | None = None,
) -> dict:
    """The record of one run (plain JSON).

    Args:
        command: e.g. ``"sweep"``, ``"tune"``, ``"simulate sim1"``.
        config: the configuration as parsed (any mix of dicts, dataclasses, arrays, paths).
        seeds: named random seeds (e.g. ``{"sweep": 0}``, ``{"train": 0, "heldout": 1001}``).
        wall_s: wall time [s], a number or named parts (``{"total": ..., "compile": ...}``).
        argv: the command line (default ``sys.argv``).
        extra: anything else worth keeping (merged in last).
    """
    import vcjax
    from vcjax.runtime.cache import cache_dir, cache_off_reason

    devices = jax.devices()
    info = {
        "command": command,
        "argv": list(sys.argv if argv is None else argv),
        "finished_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "vcjax": {"version": vcjax.__version__, "git": git_commit()},
        "versions": {
            "python": platform.python_version(),
            "jax": jax.__version__,
            "jaxlib": _version("jaxlib"),
            "numpy": np.__version__,
            "optax": _version("optax"),
        },
        "x64": bool(jax.config.jax_enable_x64),
        "platform": platform.platform(),
        "backend": jax.default_backend(),
        "devices": {
            "count": len(devices),
            "local_count": jax.local_device_count(),
            "kinds": sorted({d.device_kind for d in devices}),
        },
        "processes": {"count": jax.process_count(), "index": jax.process_index()},
        "compilation_cache": cache_dir(),
        **({"compilation_cache_off": cache_off_reason()} if cache_off_reason() else {}),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "programs": _programs(),
        "config": to_jsonable(config),
        "seeds": to_jsonable(seeds or {}),
        "wall_s": to_jsonable(wall_s),
    }
    if extra:
        info.update(to_jsonable(extra))
    return info


def _programs() -> dict:
    """The lowered-program store's folder and what this run built or reused from it."""
    from vcjax.runtime import programs

    folder = programs.store_dir()
    out = {"store": None if folder is None else str(folder), "built": programs.report()}
    if programs.off_reason():
        out["store_off"] = programs.off_reason()
    return out


def write_run_json(out_dir, command: str, **kwargs) -> Path | None:
    """Write [`run_info`][vcjax.runtime.runinfo.run_info] to ``out_dir/run.json``; returns the path
    (None on processes other
    than 0 of a multi-process run, which write nothing)."""
    if jax.process_index() != 0:
        return None
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "run.json"
    from vcjax.runtime.outputs import write_json_atomic

    return write_json_atomic(path, run_info(command, **kwargs))
