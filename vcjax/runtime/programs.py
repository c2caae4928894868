"""Lowered programs kept on disk, so that a second identical ``vcjax`` command does not trace.

JAX's persistent compilation cache ([`vcjax.runtime.cache`][vcjax.runtime.cache]) keeps XLA's
executables, but it
finds them by hashing the lowered program: every run still traces the closed loop in Python and
lowers it first (REMUS 100's batch program: seconds). This store keeps the lowered program itself,
serialised with [`jax.export`][vcjax.runtime.programs.jax.export], in ``programs/`` inside the
compilation cache's folder, keyed
by a SHA-256 of everything that can change it:

* the program's name and its static inputs, described field by field
([`describe`][vcjax.runtime.programs.describe]: the loop
  dataclass with its path function's module, name, code and closure, the rollout settings);
* the argument pytree's structure and every leaf's shape, dtype and sharding (values are traced
  inputs: gains and scenarios never enter the key, so new values reuse the program);
* the vcjax version and a hash of every ``.py`` file of the ``vcjax`` and ``tuning`` packages
  (so an edited checkout never reuses a program its old code traced), the jax and jaxlib
  versions, ``XLA_FLAGS``, JAX's configuration (x64, dtype promotion, matmul precision, ...),
  the backend and its devices.

Used by ``vcjax sweep`` (each controller's batch program), ``vcjax tune`` (held-out evaluation,
figures' trajectories, the training step's value-and-gradient), ``vcjax simulate NAME`` (each
variant's rollout) and ``vcjax fit`` (residuals, Jacobians, free runs). A file holds the
program's output tree (pickled: ``jax.export`` serialises only the pytree nodes it knows, so the
exported function returns the flattened outputs) and the serialised export; an output tree
``pickle`` cannot name (a class defined inside a function) is built as before, not stored.

Multi-process runs (``vcjax launch``) build their programs as before, one after another. A
static input that cannot be described stably (an object whose ``repr`` holds a memory address,
a function closing over something else) is not stored: the program is built as before.

[`build`][vcjax.runtime.programs.build] is the one entry point. With the store on, a program is
always compiled from its
exported form (the first run exports and saves it, then compiles the loaded form exactly as the
second run will), so the first and second runs compile the same module and the second reads
XLA's executable back from the persistent cache: no tracing, no compiling. With the store off
(``VCJAX_CACHE_DIR=off``, or the compilation cache off) it is ``jax.jit(f).lower(...).compile()``
as before. The store is bounded ([`MAX_BYTES`][vcjax.runtime.programs.MAX_BYTES]; least recently
used files removed first) and
the library never turns it on by itself:
[`enable_compilation_cache`][vcjax.runtime.cache.enable_compilation_cache]
(the command line) does. [`report`][vcjax.runtime.programs.report] lists what this process built or
reused (``run.json``'s
``"programs"``).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import importlib.util
import os
import pickle
import sys
import sysconfig
import threading
import time
import types
from pathlib import Path

import jax
import numpy as np

from vcjax.runtime import compiler

__all__ = [
    "MAX_BYTES",
    "build",
    "argument_spec",
    "build_all",
    "describe",
    "for_arguments_like",
    "evict",
    "off_reason",
    "program_key",
    "report",
    "set_store",
    "store_dir",
]

#: the store's size bound (least recently used programs removed beyond it)
MAX_BYTES = 512 * 1024**2
#: the file name's suffix (one file per program)
SUFFIX = ".jaxexport"
#: the environment variable that turns the store off alone (the compilation cache stays on)
STORE_ENV = "VCJAX_PROGRAM_STORE"
_OFF = ("off", "none", "0", "false", "no")
#: the environment variable that caps `build_all`'s threads (1:
#: serial)
WORKERS_ENV = "VCJAX_COMPILE_WORKERS"
_FORMAT = 2  # bump when the key's material or the file layout changes
#: a stored file: this, the pickled output tree's length (8 bytes), the tree, the export
_MAGIC = b"vcjax-program\x00"

_STORE: list[Path | None] = [None]
_REPORT: list[dict] = []
_OFF_REASON: list[str] = []
_LOCK = threading.Lock()
#: held while a program is traced, exported or loaded and lowered (Python's part, which holds
#: the GIL), not while XLA compiles it (outside the GIL, on threads of its own):
#: `build_all`'s threads trace one after another, so the
#: first program's compile starts when its own trace ends (on the cores the tracing leaves
#: free) instead of when every trace, interleaved, has ended
_TRACING = threading.RLock()


class Unstable(Exception):
    """A static input whose description would not be the same in another process."""


def _export():
    """``jax.export`` (a submodule older JAX releases do not import with ``jax``)."""
    from jax import export

    return export


def set_store(path) -> Path | None:
    """Use ``path`` (a folder, created on demand) for the store; None turns it off. Called by
    [`enable_compilation_cache`][vcjax.runtime.cache.enable_compilation_cache] with
    ``<cache>/programs``. Stays off
    ([`off_reason`][vcjax.runtime.programs.off_reason] says why) with ``VCJAX_PROGRAM_STORE=off``
    and where [`jax.export`][vcjax.runtime.programs.jax.export]
    cannot serialise (it needs the ``flatbuffers`` package)."""
    _REPORT.clear()
    _OFF_REASON.clear()
    if path is not None and os.environ.get(STORE_ENV, "").strip().lower() in _OFF:
        _OFF_REASON.append(f"{STORE_ENV}={os.environ[STORE_ENV]}")
        path = None
    if path is not None and importlib.util.find_spec("flatbuffers") is None:
        _OFF_REASON.append("the 'flatbuffers' package (jax.export's serialisation) is missing")
        path = None
    _STORE[0] = None if path is None else Path(path)
    return _STORE[0]


def off_reason() -> str | None:
    """Why [`set_store`][vcjax.runtime.programs.set_store] left the store off although asked for a
    folder (None: it did not)."""
    return _OFF_REASON[0] if _OFF_REASON else None


def store_dir() -> Path | None:
    """The folder of the store in this process (None: off)."""
    return _STORE[0]


def report() -> list[dict]:
    """What [`build`][vcjax.runtime.programs.build] did in this process, one entry per program:
    ``name``, ``key`` (None:
    not storable), ``reused`` (loaded from the store, not traced), ``build_s`` (export or load,
    lower and compile)."""
    with _LOCK:
        return [dict(r) for r in _REPORT]


# ----------------------------------------------------------------------------- the key


def describe(x, _depth: int = 0):
    """A plain, process-independent description of a static value (raises
    [`Unstable`][vcjax.runtime.programs.Unstable])."""
    if _depth > 40:
        raise Unstable("too deep")
    d = _depth + 1
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return (type(x).__name__, repr(x))
    if isinstance(x, enum.Enum):
        return ("enum", _qualname(type(x)), x.name)
    if isinstance(x, type):
        return ("type", _qualname(x))
    if isinstance(x, (np.ndarray, np.generic, jax.Array)):
        a = np.asarray(x)
        return ("array", str(a.dtype), a.shape, hashlib.sha256(a.tobytes()).hexdigest())
    if isinstance(x, np.dtype):
        return ("dtype", str(x))
    if dataclasses.is_dataclass(x):
        return (
            "dataclass",
            _qualname(type(x)),
            tuple((f.name, describe(getattr(x, f.name), d)) for f in dataclasses.fields(x)),
        )
    if isinstance(x, tuple) and hasattr(x, "_fields"):  # NamedTuple
        return (
            "namedtuple",
            _qualname(type(x)),
            tuple(describe(v, d) for v in x),
        )
    if isinstance(x, (tuple, list)):
        return (type(x).__name__, tuple(describe(v, d) for v in x))
    if isinstance(x, (frozenset, set)):
        return ("set", tuple(sorted(repr(describe(v, d)) for v in x)))
    if isinstance(x, dict):
        return ("dict", tuple(sorted((repr(describe(k, d)), describe(v, d)) for k, v in x.items())))
    if isinstance(x, functools.partial):
        return ("partial", describe(x.func, d), describe(x.args, d), describe(x.keywords, d))
    if isinstance(x, types.FunctionType):
        code = x.__code__
        cells = tuple(describe(c.cell_contents, d) for c in (x.__closure__ or ()))
        return (
            "function",
            x.__module__,
            x.__qualname__,
            hashlib.sha256(code.co_code + repr(code.co_consts).encode()).hexdigest(),
            cells,
            describe(x.__defaults__, d),
            describe(x.__kwdefaults__, d),
        )
    if isinstance(x, (types.BuiltinFunctionType, types.ModuleType)):
        return ("named", getattr(x, "__module__", None), getattr(x, "__name__", None))
    r = repr(x)
    if " at 0x" in r or "object at" in r:
        raise Unstable(f"cannot describe {type(x).__qualname__}")
    return ("repr", _qualname(type(x)), r)


def _qualname(t: type) -> str:
    return f"{t.__module__}.{t.__qualname__}"


def source_hash() -> str:
    """SHA-256 over every ``.py`` file of the ``vcjax`` and ``tuning`` packages (path and bytes)."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[2]
    for pkg in ("vcjax", "tuning"):
        for path in sorted((root / pkg).rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _installed_roots() -> tuple[Path, ...]:
    paths = sysconfig.get_paths()
    roots = {paths.get(k) for k in ("stdlib", "platstdlib", "purelib", "platlib")}
    return tuple(Path(r).resolve() for r in roots if r)


def user_sources() -> tuple:
    """``(path, sha256)`` of every module loaded in this process from a file that is neither
    vcjax's nor tuning's ([`source_hash`][vcjax.runtime.programs.source_hash]) nor part of Python or
    an installed package: the
    laws, loops and components a config imports (``[scenario] module``), whose code is traced
    into the programs. An edit anywhere in such a file changes the key."""
    own = Path(__file__).resolve().parents[2]
    skip = (*_installed_roots(), own / "vcjax", own / "tuning")
    out = []
    for mod in list(sys.modules.values()):
        f = getattr(mod, "__file__", None)
        if not f or not f.endswith(".py"):
            continue
        path = Path(f).resolve()
        if any(part in ("site-packages", "dist-packages") for part in path.parts):
            continue
        if any(path.is_relative_to(root) for root in skip):
            continue
        try:
            out.append((str(path), hashlib.sha256(path.read_bytes()).hexdigest()))
        except OSError:
            continue
    return tuple(sorted(set(out)))


_SKIP_CONFIG = ("cache", "log", "dump", "pprint", "traceback", "debug_info", "explain")


def environment() -> tuple:
    """What outside the program changes its lowering or compilation in this process."""
    import jaxlib

    cfg = tuple(
        (k, repr(v))
        for k, v in sorted(jax.config.values.items())
        if not any(s in k for s in _SKIP_CONFIG)
    )
    devs = jax.devices()
    return (
        ("format", _FORMAT),
        ("vcjax", source_hash()),  # vcjax/__init__.py, its version included
        ("user_code", user_sources()),
        ("jax", jax.__version__, jaxlib.__version__),
        ("xla_flags", os.environ.get("XLA_FLAGS", "")),
        ("config", cfg),
        ("backend", jax.default_backend(), len(devs), tuple(sorted({d.device_kind for d in devs}))),
        ("processes", jax.process_count()),
    )


def _leaf_spec(leaf) -> tuple:
    sharding = getattr(leaf, "sharding", None)
    dtype = leaf.dtype if hasattr(leaf, "dtype") else np.asarray(leaf).dtype
    return (tuple(np.shape(leaf)), str(dtype), str(sharding),
            bool(getattr(leaf, "weak_type", False)))  # fmt: skip


def _committed(leaf) -> bool:
    """Whether ``leaf``'s placement is part of the program: a committed array, or a
    ``jax.ShapeDtypeStruct`` that names a sharding (it stands for one)."""
    if isinstance(leaf, jax.ShapeDtypeStruct):
        return leaf.sharding is not None
    return bool(getattr(leaf, "committed", False))


def argument_spec(args) -> tuple:
    """The part of the key that ``args`` give: tree structure and each leaf's shape, dtype,
    sharding and weak type (a program built for one spec runs only on arguments of that spec)."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    return (str(treedef), tuple(_leaf_spec(leaf) for leaf in leaves))


def program_key(name: str, static, args) -> str:
    """The store's key of program ``name`` with static inputs ``static`` at ``args`` (a tuple of
    pytrees: only their structure, shapes, dtypes and shardings count); raises
    [`Unstable`][vcjax.runtime.programs.Unstable] when ``static`` cannot be described."""
    material = (("name", name), ("static", describe(static)), argument_spec(args), environment())
    return hashlib.sha256(repr(material).encode()).hexdigest()


# ----------------------------------------------------------------------------- building


def build(name: str, fn, static, args: tuple, *, record: bool = True):
    """Compile ``fn(*args)`` (``fn`` with its static inputs bound; ``static``: those inputs, for
    the key) and return ``(call, info)``: ``call(*args)`` runs the compiled program on new values
    of the same shapes and returns what ``fn`` returns (any pytree of arrays); ``info`` is this
    program's [`report`][vcjax.runtime.programs.report] entry (``record=False``: not added to
    it). A leaf of ``args`` may be a ``jax.ShapeDtypeStruct`` (with a sharding: it stands for an
    array committed there), so a program can be built before its inputs exist.

    With the store on, the program is loaded from it when an identical one was stored (no
    tracing), else exported, stored and loaded back; either way compiled from the exported
    form, so the persistent compilation cache finds the executable a previous run compiled.
    """
    t0 = time.perf_counter()
    # one process only: a multi-process run's arguments are global arrays (not exported here)
    folder = store_dir() if jax.process_count() == 1 else None
    key = None
    with _TRACING:  # Python's part, one program at a time (see _TRACING); compiled outside
        if folder is not None:
            try:
                key = program_key(name, static, args)
            except Unstable:
                key = None
        leaves, treedef = jax.tree_util.tree_flatten(args)
        loaded = None if key is None else _load(folder, key)
        reused = loaded is not None
        if key is not None and loaded is None:
            loaded = _export_and_store(folder, key, fn, treedef, leaves)
        if loaded is None:  # not storable (a static input, or the outputs' structure)
            key = None
            lowered, out_tree = compiler.jit(fn).lower(*args), None
        else:
            exp, out_tree = loaded
            lowered = compiler.jit(exp.call).lower(*leaves)
    compiled = lowered.compile()
    if out_tree is None:
        call = compiled
    else:

        def call(*a):
            return jax.tree_util.tree_unflatten(out_tree, compiled(*jax.tree_util.tree_leaves(a)))

    info = {"name": name, "key": None if key is None else key[:16], "reused": reused}
    info["build_s"] = round(time.perf_counter() - t0, 3)
    if record:
        with _LOCK:
            _REPORT.append(info)
    return call, dict(info)


def _export_and_store(folder: Path, key: str, fn, treedef, leaves):
    """Export ``fn`` at ``leaves`` (its outputs flattened: ``jax.export`` serialises only the
    pytrees it knows), store it and return it as loaded back, ``(exported, output tree)``; None
    when the output tree cannot be stored (a class ``pickle`` cannot name)."""
    out_tree = []

    def flat(*xs):
        out, tree = jax.tree_util.tree_flatten(fn(*jax.tree_util.tree_unflatten(treedef, xs)))
        out_tree.append(tree)
        return out

    # a committed array's placement is part of the program; an uncommitted one (a new array on
    # the default device) goes where the others are, as with jax.jit
    shardings = tuple(x.sharding if _committed(x) else None for x in leaves)
    if all(s is None for s in shardings):
        jitted = jax.jit(flat)
    else:
        jitted = jax.jit(flat, in_shardings=shardings)
    program = bytes(_export().export(jitted)(*leaves).serialize())
    try:
        tree = pickle.dumps(out_tree[-1], protocol=4)
        if pickle.loads(tree) != out_tree[-1]:
            return None
    except Exception:  # a local class, or one pickle cannot import back
        return None
    blob = _pack(tree, program)
    _save(folder, key, blob)
    # compiled from the form read back, as the next run will compile it (the same module:
    # the persistent cache's key)
    return _unpack(blob)


def _pack(tree: bytes, program: bytes) -> bytes:
    return _MAGIC + len(tree).to_bytes(8, "little") + tree + program


def _unpack(blob: bytes):
    """``(exported, output tree)`` of a stored file; raises on a damaged or foreign one."""
    if not blob.startswith(_MAGIC):
        raise ValueError("not a program of this store")
    n = int.from_bytes(blob[len(_MAGIC) : len(_MAGIC) + 8], "little")
    start = len(_MAGIC) + 8
    tree = pickle.loads(blob[start : start + n])
    return _export().deserialize(bytearray(blob[start + n :])), tree


def for_arguments_like(call, args, fallback):
    """``call`` (a built program, e.g. from `build_all`) for
    arguments of the spec of ``args`` ([`argument_spec`][vcjax.runtime.programs.argument_spec]:
    structure, shapes, dtypes, shardings), ``fallback`` (e.g. the jitted function) for any
    other: a program built ahead of time for one batch, still right for another."""
    spec = argument_spec(args)

    def run(*a):
        return call(*a) if argument_spec(a) == spec else fallback(*a)

    return run


def build_all(jobs, workers: int | None = None) -> list:
    """[`build`][vcjax.runtime.programs.build] every ``(name, fn, static, args)`` of ``jobs``
    concurrently (threads: XLA
    compiles outside Python's lock, so independent programs compile in parallel on several
    cores); returns their ``(call, info)`` in order. ``workers`` defaults to
    ``$VCJAX_COMPILE_WORKERS`` (1: one after another), else the CPU count; ``info["build_s"]``
    is each program's own wall time (they overlap)."""
    jobs = list(jobs)
    if workers is None:
        env = os.environ.get(WORKERS_ENV, "").strip()
        workers = int(env) if env.isdigit() and int(env) > 0 else (os.cpu_count() or 1)
    if jax.process_count() > 1:  # every process builds its programs in the same order
        workers = 1
    workers = min(len(jobs), workers)
    if workers <= 1:
        return [build(*job) for job in jobs]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="vcjax-compile") as pool:
        built = list(pool.map(lambda job: build(*job, record=False), jobs))
    with _LOCK:  # the report in the jobs' order, whichever finished first
        _REPORT.extend(dict(info) for _, info in built)
    return built


def _path(folder: Path, key: str) -> Path:
    return folder / f"{key}{SUFFIX}"


def _load(folder: Path, key: str):
    """``(exported, output tree)`` stored under ``key``; None when absent or unreadable."""
    path = _path(folder, key)
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        loaded = _unpack(blob)
    except Exception:  # a truncated or foreign file: rebuild (and overwrite it)
        return None
    try:
        os.utime(path)  # most recently used
    except OSError:
        pass
    return loaded


def _save(folder: Path, key: str, blob: bytes) -> None:
    """Write atomically (a temporary file renamed), then keep the folder under
    [`MAX_BYTES`][vcjax.runtime.programs.MAX_BYTES]
    by removing the least recently used files. A folder that cannot be written is skipped."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / f".{key}.{os.getpid()}.{threading.get_ident()}.tmp"
        tmp.write_bytes(blob)
        os.replace(tmp, _path(folder, key))
        evict(folder, MAX_BYTES)
    except OSError:
        pass


def evict(folder: Path, max_bytes: int) -> list[Path]:
    """Remove the least recently used programs of ``folder`` until the rest fit in
    ``max_bytes``; returns the removed files."""
    files = []
    for p in Path(folder).glob(f"*{SUFFIX}"):
        try:
            st = p.stat()
        except OSError:
            continue
        files.append((st.st_mtime, st.st_size, p))
    files.sort()
    total = sum(size for _, size, _ in files)
    removed = []
    for _, size, p in files:
        if total <= max_bytes:
            break
        try:
            p.unlink()
        except OSError:
            continue
        total -= size
        removed.append(p)
    return removed
