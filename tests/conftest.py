"""Test configuration: float64 and strict dtype promotion for every test; one persistent
compilation cache per test session; the CLI's XLA CPU code generator.

The library itself never flips these switches; only the tests do.

Compilation cache: the CLI turns on JAX's persistent compilation cache (:mod:`vcjax.runtime.cache`);
tests, run in-process or in subprocesses, must never read or fill the user's folder. They share
a fresh folder of their own instead, one per test session: the xdist workers of a run (one
folder named after the run's id) and the ``vcjax`` subprocesses they start (through
``VCJAX_CACHE_DIR``). A program the session already compiled -- the same loop built by another
test, another worker or a CLI run -- is read back instead of compiled again. Nothing outlives
the session (the folder is removed at its end), so no test sees entries of an earlier run; the
tests of the cache itself (``test_cache.py``) use folders of their own.

The checkout stays as it was: tests write into ``tmp_path`` only. The run records every file of
the repository (name, size, modification time; build outputs and caches left out:
:data:`_NOT_WATCHED`) when it starts and again when it ends, and fails naming any file that was
created, changed or removed (e.g. a command writing its default ``out/`` into the checkout, or
depending on what the README's main job left there).
"""

import os
import shutil
import tempfile
from pathlib import Path

import jax
import pytest

from vcjax.runtime.cache import enable_compilation_cache
from vcjax.runtime.compiler import prefer_fast_compile

_PREFIX = "vcjax-test-jax-cache-"


def _session_cache_dir() -> Path:
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")  # the same in every worker of one run
    if run:
        path = Path(tempfile.gettempdir()) / f"{_PREFIX}{run}"
        path.mkdir(exist_ok=True)
        return path
    return Path(tempfile.mkdtemp(prefix=_PREFIX))


# XLA's faster-compiling CPU kernel generator, as the CLI uses it (vcjax.runtime.compiler); inherited by
# the subprocesses the tests start (before JAX starts: XLA reads its flags once)
prefer_fast_compile()

if "VCJAX_TEST_CACHE_DIR" not in os.environ:  # set once, by the first process of the run
    os.environ["VCJAX_TEST_CACHE_DIR"] = str(_session_cache_dir())
os.environ["VCJAX_CACHE_DIR"] = os.environ["VCJAX_TEST_CACHE_DIR"]
enable_compilation_cache()

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")


#: The checkout watched (``VCJAX_TEST_CHECKOUT``: another folder, for the test of this check).
_REPO = Path(os.environ.get("VCJAX_TEST_CHECKOUT") or Path(__file__).resolve().parents[1])
#: Folders of the checkout the tests may change: the interpreter's and tools' caches and the
#: virtual environments (ignored build outputs, never results).
_NOT_WATCHED = {
    ".git",
    ".venv",
    ".venv-min",
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    ".mypy_cache",
    ".hypothesis",
}


def _repo_files() -> dict[str, tuple[int, int]]:
    """``relative path -> (size, mtime_ns)`` of every file of the checkout (:data:`_NOT_WATCHED`
    folders and ``*.egg-info`` left out)."""
    files = {}
    for root, dirs, names in os.walk(_REPO):
        dirs[:] = [d for d in dirs if d not in _NOT_WATCHED and not d.endswith(".egg-info")]
        for n in names:
            p = os.path.join(root, n)
            try:
                st = os.stat(p)
            except OSError:
                continue
            files[os.path.relpath(p, _REPO)] = (st.st_size, st.st_mtime_ns)
    return files


def checkout_changes(before: dict, after: dict) -> list[str]:
    """Files created (``+``), changed (``~``) or removed (``-``) between two
    :func:`_repo_files` snapshots."""
    return sorted(
        [f"+ {k}" for k in after.keys() - before.keys()]
        + [f"- {k}" for k in before.keys() - after.keys()]
        + [f"~ {k}" for k in after.keys() & before.keys() if after[k] != before[k]]
    )


def pytest_configure(config):
    """The default run (``-m "not slow"``, the README's test command) compiles at XLA's backend
    optimisation level 0: LLVM's machine-code passes off, the XLA graph the one users compile.
    A test mostly compiles small programs and runs them a few steps, and this level compiles
    them about a third faster (the default run: about a quarter less time). A result can differ
    in its last bit where LLVM would have fused a multiply-add: a default test that needs exact
    binary sums compiles its program at the default level (test_identify_power2's zigzag), and
    the subprocesses of the multi-process tests keep the parent's level. Any other selection
    (``-m slow``: bit-identity across processes and devices, the figure reproductions whose
    tunes amplify a last bit) runs at XLA's default level (3 on the CPU), as users do.
    ``VCJAX_TEST_XLA_OPT=N`` (or an ``XLA_FLAGS`` that sets the level) chooses it for any run.
    Set here, before the first test starts JAX's backend (XLA reads its flags once); xdist's
    workers get the same ``-m``."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" in flags:
        return
    level = os.environ.get("VCJAX_TEST_XLA_OPT")
    if level is None and (config.getoption("markexpr", "") or "").strip() == "not slow":
        level = "0"
    if level is not None:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_backend_optimization_level={level}".strip()


def pytest_sessionstart(session):
    if os.environ.get("PYTEST_XDIST_WORKER") is None:  # the controller, or a run without workers
        session.config._vcjax_checkout = _repo_files()
        _check_entry_points()


def _check_entry_points():
    """``vcjax tune`` is found through the package metadata (vcjax.plugins): one clear line,
    instead of every tune test failing, when it was never installed from this checkout."""
    from importlib.metadata import entry_points

    want = {("vcjax.commands", "tune"), ("vcjax.metrics", "loss")}
    if not all(any(ep.name == n for ep in entry_points(group=g)) for g, n in want):
        raise pytest.UsageError(
            "the 'vcjax.commands' / 'vcjax.metrics' entry points (`vcjax tune`, the tuner's "
            "loss metric) are not installed: run "
            "`pip install -e .` in the checkout (pyproject.toml declares them)"
        )


def pytest_sessionfinish(session):
    # the controller (or a run without workers) removes the folder once every test is done
    path = Path(os.environ["VCJAX_TEST_CACHE_DIR"])
    if os.environ.get("PYTEST_XDIST_WORKER") is None and path.name.startswith(_PREFIX):
        shutil.rmtree(path, ignore_errors=True)
    before = getattr(session.config, "_vcjax_checkout", None)
    if before is None:
        return
    changed = checkout_changes(before, _repo_files())
    if changed:
        tr = session.config.pluginmanager.get_plugin("terminalreporter")
        lines = [f"the test run wrote into the checkout {_REPO} (tests must use tmp_path):"]
        lines += [f"  {c}" for c in changed[:20]] + (
            [f"  ... {len(changed) - 20} more"] * (len(changed) > 20)
        )
        for line in lines:
            if tr is not None:
                tr.write_line(line, red=True)
            else:
                print(line)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
