"""Output folders that lose nothing and clobber nothing: checks before any work, a lock, atomic
writes.

Every ``vcjax`` command that writes a folder (``simulate``, ``sweep``, ``tune``, ``fit``) calls
[`prepare_out`][vcjax.runtime.outputs.prepare_out] before it compiles or runs anything:

* ``--out`` must be creatable and writable (a file in the way, a read-only parent, a folder
  without write permission: exit 2 naming it). Checked by creating the folder and writing (then
  removing) a probe file, so what is reported is what the operating system allows.
* A non-empty ``--out`` that holds another vcjax run (its manifest ``MANIFEST``, or one of
  ``MARKERS`` from a vcjax that wrote no manifest) is refused unless ``--overwrite`` is
  given. With it, exactly the files the earlier run's manifest lists are removed (its data
  files and figures): nothing is matched by name, so a user's own ``metrics.json`` stays, and a
  file that is an input of the command (``keep``: the config, a gains file, every file the
  config names) is never removed. The commands call
  [`prepare_out`][vcjax.runtime.outputs.prepare_out] only after every
  check of their inputs passed, so a bad input leaves the earlier results untouched.
* A lock file (``LOCK``, holding ``pid``, host, the process's start time and the command)
  makes one writer per folder: a second process writing the same ``--out`` gets exit 2 naming
  the holder. The lock is created whole (a temporary file hard-linked into place) and released
  when the process ends (``atexit``; also by
  [`OutDir.release`][vcjax.runtime.outputs.OutDir.release]). A lock that is empty or
  unparsable, or whose process (same host) is gone or is now another program (a reused PID:
  another start time), is stale and taken over.

In a multi-process run (``vcjax launch``) only process 0 checks contents, locks and writes the
shared files; the others only check that the folder is writable (they write their
``results.part`` files there). The rank is the distributed runtime's
([`process_rank`][vcjax.runtime.outputs.process_rank]):
environment variables alone never make a process skip the checks.

Writes are atomic ([`write_json_atomic`][vcjax.runtime.outputs.write_json_atomic],
[`save_npz_atomic`][vcjax.runtime.outputs.save_npz_atomic],
[`savefig_atomic`][vcjax.runtime.outputs.savefig_atomic]):
a temporary file in the same folder, then ``os.replace``, so a killed run never leaves a
half-written JSON or npz behind.

Interrupts that keep what is done: ``vcjax.runtime.interrupts``.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import socket
import tempfile
from pathlib import Path

import numpy as np

__all__ = [
    "LOCK",
    "MANIFEST",
    "MARKERS",
    "OutDir",
    "OutputError",
    "process_rank",
    "prepare_out",
    "save_npz_atomic",
    "savefig_atomic",
    "write_atomic",
    "write_json_atomic",
]

#: Lock file name inside ``--out``.
LOCK = ".vcjax.lock"
#: Manifest of the files a run wrote (read by ``--overwrite`` to remove exactly those).
MANIFEST = ".vcjax-files.json"
#: Files only vcjax writes: their presence means the folder holds a vcjax run. (``gains.json``
#: is not one: users keep gains files as inputs; a run's own is listed in its manifest.)
MARKERS = (
    "run.json",
    "summary.json",
    "results.npz",
    "results.nc",
    "fit.json",
    "metrics.json",
    "history.json",
)


class OutputError(ValueError):
    """An unusable ``--out`` (the CLI prints it as one line, exit code 2)."""


# --------------------------------------------------------------------------- atomic writes


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _tmp_for(path: Path) -> Path:
    """A temporary file beside ``path``, with the permissions a plain ``open`` would give it
    (``mkstemp`` makes it private, 0600)."""
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
    finally:
        os.close(fd)
    return Path(name)


def _replace(tmp: Path, path: Path) -> Path:
    try:
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


def write_atomic(path, write) -> Path:
    """``write(tmp)`` to a temporary file beside ``path``, then rename it onto ``path``; the
    temporary is removed if writing fails (``path`` keeps its old content). For writers that
    take a file name (``xarray.Dataset.to_netcdf``, ...); JSON, npz and figures have their own
    helpers below."""
    path = Path(path)
    tmp = _tmp_for(path)
    try:
        write(tmp)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return _replace(tmp, path)


def _synced(mode: str, write):
    """A ``write(tmp)`` that opens ``tmp`` in ``mode``, calls ``write(f)`` and syncs to disk."""

    def run(tmp):
        with open(tmp, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())

    return run


def write_json_atomic(path, obj, indent: int | None = 2, newline: bool = True, **kwargs) -> Path:
    """Write ``obj`` as JSON (plus a newline unless ``newline=False``) to ``path`` atomically;
    returns the path.

    ``kwargs`` go to ``json.dumps`` (e.g. ``allow_nan=False``); an object that cannot be
    serialised raises before anything is written."""
    text = json.dumps(obj, indent=indent, **kwargs) + ("\n" if newline else "")
    return write_atomic(path, _synced("w", lambda f: f.write(text)))


def save_npz_atomic(path, compressed: bool = True, **arrays) -> Path:
    """``np.savez_compressed(path, **arrays)`` (``np.savez`` unless ``compressed``), atomically."""
    save = np.savez_compressed if compressed else np.savez
    return write_atomic(path, _synced("wb", lambda f: save(f, **arrays)))


def savefig_atomic(fig, path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` through a temporary file (format from ``path``'s suffix
    unless ``format`` is given), then ``os.replace``."""
    kwargs.setdefault("format", Path(path).suffix.lstrip(".") or None)
    return write_atomic(path, lambda tmp: fig.savefig(tmp, **kwargs))


# --------------------------------------------------------------------------- output folder


def process_rank() -> int:
    """This process's index in a multi-process run: the distributed runtime's
    (``jax.process_index()`` once
    [`initialize_from_env`][vcjax.runtime.distributed.initialize_from_env] has
    joined one), else 0. Environment variables alone (``SLURM_PROCID`` outside a real step, a
    stray ``VCJAX_PROCESS_ID``) never make a process a non-writer: only a joined run does."""
    from vcjax.runtime import distributed

    return distributed.process_index()


def _start_time(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot, ``/proc/PID/stat`` field
    22), or None where ``/proc`` cannot tell. A PID reused by another program has another."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2 :].split()  # after the command name (may hold spaces)
    return fields[19] if len(fields) > 19 else None


def _runs_vcjax(pid: int) -> bool | None:
    """Whether process ``pid``'s command line mentions vcjax (None: cannot tell)."""
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    return b"vcjax" in cmd


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _lock_is_stale(holder: dict | None) -> bool:
    """A lock nobody holds: empty or unparsable (locks are created whole, never half-written),
    no integer PID, or on this host a PID that is gone or now another program (its start time
    differs from the one recorded; a lock without one: a process that does not run vcjax)."""
    if holder is None or not isinstance(holder.get("pid"), int) or isinstance(holder["pid"], bool):
        return True
    pid, host = holder["pid"], holder.get("host")
    if host not in (None, socket.gethostname()):
        return False  # another machine's process: cannot tell, respected
    if pid == os.getpid():
        return True  # left by an earlier command of this process
    if not _pid_alive(pid):
        return True
    if holder.get("start") is not None:
        now = _start_time(pid)
        return now is not None and now != str(holder["start"])
    return _runs_vcjax(pid) is False


class OutDir:
    """A checked, locked output folder (from [`prepare_out`][vcjax.runtime.outputs.prepare_out]).

    Attributes:
        path: the folder; writer: whether this process writes the shared files (process 0);
        removed: the files ``--overwrite`` removed.
    """

    def __init__(self, path: Path, writer: bool, removed: list[Path]):
        self.path, self.writer, self.removed = path, writer, removed
        self._locked = False
        self._before: dict[str, int] = {}
        #: ``(command, args)`` of the run writing here (set by the CLI; for ``run.json``)
        self.run = None

    def _snapshot(self) -> dict[str, int]:
        """``relative name -> mtime_ns`` of every file below the folder (lock, manifest and
        temporary files left out)."""
        snap = {}
        for root, _, names in os.walk(self.path):
            for n in names:
                if n in (LOCK, MANIFEST) or n.endswith(".tmp") or n.startswith(".vcjax-probe."):
                    continue
                p = Path(root) / n
                with contextlib.suppress(OSError):
                    snap[str(p.relative_to(self.path))] = p.stat().st_mtime_ns
        return snap

    def record_written(self) -> Path | None:
        """Write the manifest ``MANIFEST``: every file created or rewritten since
        [`prepare_out`][vcjax.runtime.outputs.prepare_out] (what ``--overwrite`` of a later run
        removes; a user's file that
        was there before and left alone is not listed)."""
        if not self.writer:
            return None
        names = sorted(set(self.written()) | set(_read_manifest(self.path)))
        if not names:  # wrote nothing (a run that failed at once): no manifest either
            return None
        return write_json_atomic(self.path / MANIFEST, {"files": names})

    def written(self) -> list[str]:
        """Files (relative names) created or rewritten since
        [`prepare_out`][vcjax.runtime.outputs.prepare_out]."""
        now = self._snapshot()
        return [n for n, t in now.items() if self._before.get(n) != t]

    def _lock(self, command: str) -> None:
        lock = self.path / LOCK
        me = {"pid": os.getpid(), "host": socket.gethostname(), "command": command}
        me["start"] = _start_time(os.getpid())
        for _ in range(3):
            try:
                _create_whole(lock, json.dumps(me))
            except FileExistsError:
                holder = _read_lock(lock)
                if _lock_is_stale(holder):
                    with contextlib.suppress(FileNotFoundError):
                        lock.unlink()
                    continue
                pid, host = holder.get("pid"), holder.get("host")
                who = f"process {pid}" + (f" on {host}" if host else "")
                what = holder.get("command", "another vcjax run")
                raise OutputError(
                    f"--out {self.path}: in use by {who} ({what}; lock file {lock}); "
                    "wait for it, or choose another --out"
                ) from None
            except OSError as err:
                raise OutputError(
                    f"--out {self.path}: cannot create the lock file: {err.strerror}"
                ) from None
            self._locked = True
            atexit.register(self.release)
            return
        raise OutputError(f"--out {self.path}: cannot take the lock file {lock}")

    def release(self) -> None:
        """Remove the lock (if this object holds it)."""
        if self._locked:
            lock = self.path / LOCK
            holder = _read_lock(lock)
            if holder is not None and holder.get("pid") == os.getpid():
                with contextlib.suppress(OSError):
                    lock.unlink()
            self._locked = False


def _create_whole(path: Path, text: str) -> None:
    """Create ``path`` holding ``text``, all at once (``FileExistsError`` if it exists): written
    to a temporary file, then hard-linked into place, so nobody ever reads it half-written."""
    tmp = _tmp_for(path)
    try:
        tmp.write_text(text)
        try:
            os.link(tmp, path)
            return
        except FileExistsError:
            raise
        except OSError:  # a file system without hard links: create exclusively, then write
            pass
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()
    fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    with os.fdopen(fd, "w") as f:
        f.write(text)


def _read_lock(lock: Path) -> dict | None:
    try:
        d = json.loads(lock.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _read_manifest(path: Path) -> list[str]:
    try:
        d = json.loads((path / MANIFEST).read_text())
        files = d.get("files", []) if isinstance(d, dict) else []
        return [f for f in files if isinstance(f, str)]
    except (OSError, ValueError):
        return []


def _earlier_run(path: Path) -> list[str]:
    """Names that show ``path`` holds an earlier vcjax run: its manifest, or (a folder from a
    vcjax without manifests) one of ``MARKERS``. Only for refusing to write there without
    ``--overwrite``: what ``--overwrite`` removes comes from the manifest alone."""
    found = [m for m in MARKERS if (path / m).is_file()]
    return found + ([MANIFEST] if (path / MANIFEST).is_file() else [])


def _vcjax_files(path: Path) -> list[Path]:
    """The files an earlier vcjax run wrote in ``path``: those its manifest lists (and that are
    still inside ``path``), then the manifest itself. Nothing is matched by name: a user's own
    ``metrics.json`` in a folder without a manifest entry for it stays."""
    found: list[Path] = []
    root = path.resolve()
    for rel in _read_manifest(path):
        p = (path / rel).resolve()
        if p.is_file() and root in p.parents and p not in found:
            found.append(p)
    if (path / MANIFEST).is_file():
        found.append(path / MANIFEST)
    return found


def _check_writable(out: Path, raw) -> None:
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {raw}: exists and is not a directory")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"--out {raw}: cannot create the directory: {parent} is a file")
            break
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"--out {raw}: cannot create the directory: {err.strerror}") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=".vcjax-probe.", dir=out)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise OutputError(f"--out {raw}: not writable: {err.strerror}") from None


def prepare_out(
    path, overwrite: bool, command: str, *, writer: bool | None = None, keep=()
) -> OutDir:
    """Check, clear (with ``overwrite``) and lock the output folder ``path`` before any work.

    Args:
        path: the ``--out`` folder (created with its parents).
        overwrite: remove an earlier vcjax run's files first instead of refusing.
        command: what runs (written into the lock file, named in messages).
        writer: whether this process writes the shared outputs (default: process 0 of a
            multi-process run, [`process_rank`][vcjax.runtime.outputs.process_rank]).
        keep: files never removed (the command's inputs, e.g. ``--gains out/gains.json``).

    Raises:
        OutputError: (a ``ValueError``) the folder cannot be created or written, holds another
            run's files (without ``overwrite``), or is locked by a live process.
    """
    if path is None or str(path).strip() == "":
        raise OutputError("--out: expected a folder name, got an empty string")
    out = Path(path)
    writer = process_rank() == 0 if writer is None else bool(writer)
    _check_writable(out, path)
    d = OutDir(out, writer, [])
    if not writer:
        return d
    d._lock(command)
    try:
        kept = {Path(k).resolve() for k in keep if k}
        old = [p for p in _vcjax_files(out) if p.resolve() not in kept]
        shown = [n for n in _earlier_run(out) if (out / n).resolve() not in kept]
        if shown and not overwrite:
            names = ", ".join(sorted(shown)[:4])
            raise OutputError(
                f"--out {path}: holds another vcjax run's files ({names}); "
                "pass --overwrite to replace them, or choose another --out"
            )
        for p in old:
            try:
                p.unlink()
            except FileNotFoundError:
                pass
            except OSError as err:
                raise OutputError(f"--out {path}: cannot remove {p}: {err.strerror}") from None
            d.removed.append(p)
    except BaseException:
        d.release()
        raise
    d._before = d._snapshot()
    return d
