"""JAX's persistent compilation cache for the ``vcjax`` command line, on by default.

A closed loop's programs take seconds to minutes to compile and nothing to run; a second
identical ``vcjax`` command reads the compiled programs back from disk instead. The folder:

* ``$VCJAX_CACHE_DIR`` when set (``off``, ``none``, ``0`` or ``false`` disable the cache);
* else ``$XDG_CACHE_HOME/vcjax/jax``;
* else ``~/.cache/vcjax/jax``.

[`enable_compilation_cache`][vcjax.runtime.cache.enable_compilation_cache] is called once at the
start of ``vcjax.cli.main``, before
anything is compiled; the library itself never turns the cache on (``import vcjax`` changes no
JAX setting), so tests and user programs get JAX's defaults unless they call it.
``run.json`` records the folder used ([`cache_dir`][vcjax.runtime.cache.cache_dir]; ``null`` when
off).

Thresholds: JAX writes an entry only for programs that took at least
``jax_persistent_cache_min_compile_time_secs`` (default 1 s) to compile. We set 0: a CLI run
also compiles dozens of small programs (scenario set-up, metrics, held-out evaluation pieces)
at 10-100 ms each on a loaded 2-core machine, which add up to seconds, while reading an entry
back costs about a millisecond; with 0 a second identical run compiles nothing at all (what the
tests check). ``jax_persistent_cache_min_entry_size_bytes`` is set to 0 (no size floor), and the
folder is capped at ``MAX_BYTES`` where the JAX version supports it and the ``filelock``
package is installed (JAX needs it to remove the least recently used entries); otherwise the
folder is not capped. Settings a JAX version does not know are skipped.

Only on JAX versions whose cache reads programs back correctly (``SAFE_FROM``): jax 0.5.1
reads back a program drawing gamma or beta random numbers (``jax.random.gamma``, the sea's
directional spreading) as one that returns a constant -- silently wrong results on a second
run. Checked: 0.5.1 wrong, 0.6.2 and 0.10.2 right; below ``SAFE_FROM`` the cache stays off
and [`cache_off_reason`][vcjax.runtime.cache.cache_off_reason] says why (``run.json`` records it).

JAX traces before it computes its cache key, so the cache alone does not spare a run the tracing;
the lowered programs themselves are kept in ``programs/`` inside the same folder
(``vcjax.runtime.programs``), turned on and off with it.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from vcjax.runtime.compiler import jaxlib_version

__all__ = [
    "ENV",
    "MAX_BYTES",
    "SAFE_FROM",
    "cache_dir",
    "cache_off_reason",
    "default_cache_dir",
    "enable_compilation_cache",
]

ENV = "VCJAX_CACHE_DIR"
OFF = ("off", "none", "0", "false", "no")
MAX_BYTES = 4 * 1024**3  # 4 GiB: a few hundred of the largest (6-DOF gradient) programs

#: the first jaxlib version whose persistent cache was checked to read programs back correctly
SAFE_FROM = (0, 6, 2)

_ACTIVE: str | None = None
_OFF_REASON: list[str] = []


def unsafe_version(version: str | None = None) -> str | None:
    """Why JAX's persistent cache must stay off with this jaxlib (None: it may be on)."""
    if version is None:
        import jaxlib

        version = jaxlib.__version__
    if jaxlib_version(3, version) < SAFE_FROM:
        safe = ".".join(map(str, SAFE_FROM))
        return (
            f"jaxlib {version} reads programs that draw gamma/beta random numbers back from "
            f"its persistent cache wrongly; the cache is used from jaxlib {safe} on"
        )
    return None


def default_cache_dir(environ=None) -> Path | None:
    """The folder the environment asks for (None: disabled); see the module docstring."""
    env = os.environ if environ is None else environ
    value = env.get(ENV)
    if value is not None and value.strip():
        if value.strip().lower() in OFF:
            return None
        return Path(value).expanduser()
    xdg = env.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg and xdg.strip() else Path.home() / ".cache"
    return base / "vcjax" / "jax"


def _update(name: str, value) -> bool:
    try:
        jax.config.update(name, value)
    except (AttributeError, KeyError, ValueError):  # a name this JAX version does not have
        return False
    return True


def enable_compilation_cache(environ=None) -> str | None:
    """Turn JAX's persistent compilation cache on in the folder of
    [`default_cache_dir`][vcjax.runtime.cache.default_cache_dir]
    (or off); returns the folder used as a string, or None when disabled or the folder cannot be
    created (the run goes on without a cache)."""
    global _ACTIVE
    path = default_cache_dir(environ)
    _OFF_REASON.clear()
    reason = unsafe_version()
    if path is not None and reason is not None:
        _OFF_REASON.append(reason)
        path = None
    if path is not None:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            path = None
    from vcjax.runtime import programs

    if path is None:
        _update("jax_enable_compilation_cache", False)
        programs.set_store(None)
        _ACTIVE = None
    else:
        _update("jax_enable_compilation_cache", True)
        _update("jax_compilation_cache_dir", str(path))
        _update("jax_persistent_cache_min_compile_time_secs", 0.0)
        _update("jax_persistent_cache_min_entry_size_bytes", 0)
        if _has_filelock():  # JAX needs it to evict entries safely
            _update("jax_compilation_cache_max_size", MAX_BYTES)
        programs.set_store(path / "programs")
        _ACTIVE = str(path)
    _reset()
    return _ACTIVE


def _reset() -> None:
    """Forget a cache state JAX may have fixed already (a program compiled before this call
    would otherwise pin "no cache" for the rest of the process)."""
    try:
        from jax._src import compilation_cache as cc  # no public reset in every version

        cc.reset_cache()
    except (ImportError, AttributeError):
        pass


def _has_filelock() -> bool:
    try:
        import filelock  # noqa: F401
    except ImportError:
        return False
    return True


def cache_dir() -> str | None:
    """The folder [`enable_compilation_cache`][vcjax.runtime.cache.enable_compilation_cache] set in
    this process (None: none)."""
    return _ACTIVE


def cache_off_reason() -> str | None:
    """Why [`enable_compilation_cache`][vcjax.runtime.cache.enable_compilation_cache] left the cache
    off although the environment asked
    for it (None: it did not, or it is on)."""
    return _OFF_REASON[0] if _OFF_REASON else None
