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
"""

import os
import shutil
import tempfile
from pathlib import Path

import jax

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


def pytest_sessionfinish(session):
    # the controller (or a run without workers) removes the folder once every test is done
    path = Path(os.environ["VCJAX_TEST_CACHE_DIR"])
    if os.environ.get("PYTEST_XDIST_WORKER") is None and path.name.startswith(_PREFIX):
        shutil.rmtree(path, ignore_errors=True)
