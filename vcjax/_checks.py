"""Eager (pre-compilation) input validation.

Every public constructor of parameters calls these in plain Python, so a user sees a ``ValueError``
that names the offending field before anything is traced or compiled. Inside ``jit`` the arrays
are tracers and the checks are skipped (health is then reported as data by the rollout).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

__all__ = [
    "ConfigError",
    "SEED_MAX",
    "key",
    "check_value",
    "as_range",
    "as_number",
    "as_int",
    "as_seed",
    "as_choice",
    "as_bool",
    "as_str",
    "as_str_list",
    "closest",
    "unknown_key",
    "is_concrete",
    "check_array",
    "check_finite",
    "check_positive",
    "check_spd",
    "float_dtype",
    "as_float_array",
    "check_params",
    "with_options",
]


def is_concrete(x) -> bool:
    """True when ``x`` holds concrete values (not a JAX tracer)."""
    try:
        np.asarray(x)
    except Exception:  # jax raises TracerArrayConversionError
        return False
    return True


def check_array(name: str, x, shape: Sequence[int | None] | None = None) -> np.ndarray | None:
    """Check shape (``None`` entries match any size) and finiteness; return a numpy view.

    Returns ``None`` (and checks nothing) when ``x`` is a tracer.
    """
    if not is_concrete(x):
        return None
    a = np.asarray(x)
    if shape is not None:
        ok = a.ndim == len(shape) and all(
            s is None or s == d for s, d in zip(shape, a.shape, strict=True)
        )
        if not ok:
            want = "(" + ", ".join("?" if s is None else str(s) for s in shape)
            want += ",)" if len(shape) == 1 else ")"
            raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    if not np.issubdtype(a.dtype, np.number) and a.dtype != np.bool_:
        raise ValueError(f"{name}: expected a numeric array, got dtype {a.dtype}")
    if np.issubdtype(a.dtype, np.inexact) and not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf values: {a}")
    return a


def check_finite(name: str, x) -> None:
    """Raise if a concrete array (or pytree leaf) contains NaN/inf."""
    check_array(name, x, None)


def check_positive(name: str, x, shape: Sequence[int | None] | None = None, strict=True) -> None:
    """Every entry must be > 0 (or >= 0 when ``strict=False``)."""
    a = check_array(name, x, shape)
    if a is None:
        return
    bad = a <= 0 if strict else a < 0
    if np.any(bad):
        rel = "> 0" if strict else ">= 0"
        raise ValueError(f"{name}: every entry must be {rel}, got {a}")


def check_spd(
    name: str, M, n: int | None = None, rtol: float = 1e-8, symmetric: bool = True
) -> None:
    """``M`` must be a square, symmetric, positive-definite matrix (of size ``n`` if given).

    With ``symmetric=False`` only its symmetric part must be positive definite (then ``M`` is
    invertible and ``x^T M x > 0``), e.g. a mass matrix whose added-mass cross terms were
    perturbed independently in a model-error study."""
    a = check_array(name, M, (n, n))
    if a is None:
        return
    if a.shape[0] != a.shape[1]:
        raise ValueError(f"{name}: expected a square matrix, got shape {a.shape}")
    scale = max(float(np.max(np.abs(a))), 1e-300)
    if symmetric and not np.allclose(a, a.T, rtol=0.0, atol=rtol * scale):
        asym = float(np.max(np.abs(a - a.T)))
        raise ValueError(f"{name}: matrix is not symmetric (max |M - M^T| = {asym:.3g})")
    eig = np.linalg.eigvalsh(0.5 * (a + a.T))
    if eig[0] <= 0:
        what = "matrix" if symmetric else "symmetric part of the matrix"
        raise ValueError(
            f"{name}: {what} is not positive definite (smallest eigenvalue {eig[0]:.3g})"
        )


def float_dtype(dtype=None):
    """``dtype`` as a numpy dtype, or JAX's default float *now* when ``None``."""
    return jnp.asarray(0.0).dtype if dtype is None else jnp.dtype(dtype)


def as_float_array(name: str, x, shape: Sequence[int | None], dtype=None):
    """Check ``x`` (shape, finiteness; ``check_array``) and return it as a float array: of
    ``dtype`` when given, else of ``x``'s own float dtype (integers: JAX's default float)."""
    check_array(name, x, shape)
    a = jnp.asarray(x)
    if dtype is not None:
        return a.astype(dtype)
    return a if jnp.issubdtype(a.dtype, jnp.floating) else a.astype(float_dtype())


def check_params(
    kind: type,
    params,
    positive: Sequence[str] = (),
    nonnegative: Sequence[str] = (),
    spd: dict | None = None,
    name: str = "params",
    symmetric: bool = True,
) -> None:
    """Eager check of a parameter ``NamedTuple`` built or edited by hand (``_replace``).

    ``params`` must be a ``kind``; every leaf finite; the fields in ``positive`` > 0, in
    ``nonnegative`` >= 0; each entry ``label: fn`` of ``spd`` maps ``params`` to a matrix that
    must be symmetric positive definite (``symmetric=False``: only its symmetric part must be
    positive definite). Tracers are skipped (checks happen outside ``jit``).

    Raises:
        ValueError: naming ``name.field`` (or the ``spd`` label).
    """
    if not isinstance(params, kind):
        raise ValueError(f"{name}: expected {kind.__name__}, got {type(params).__name__}")
    for field, value in params._asdict().items():
        if hasattr(value, "_asdict"):
            continue  # nested parameter tuples are checked by their own validator
        check_array(f"{name}.{field}", value)
    for field in positive:
        check_positive(f"{name}.{field}", getattr(params, field))
    for field in nonnegative:
        check_positive(f"{name}.{field}", getattr(params, field), strict=False)
    for label, fn in (spd or {}).items():
        check_spd(f"{name}: {label}", fn(params), symmetric=symmetric)


def with_options(cls, options, kwargs: dict, fn: str):
    """``options`` (default ``cls()``, a dataclass of settings) with the fields named in
    ``kwargs`` replaced: how a function that takes an options object keeps accepting the keyword
    arguments of its older signature. A name that is no field raises ``TypeError`` as Python
    does for ``fn``."""
    import dataclasses

    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(kwargs) - names)
    if unknown:
        raise TypeError(f"{fn}() got an unexpected keyword argument {unknown[0]!r}")
    if options is None:
        return cls(**kwargs)
    if not isinstance(options, cls):
        raise TypeError(f"{fn}(): options must be a {cls.__name__}, got {type(options).__name__}")
    return dataclasses.replace(options, **kwargs) if kwargs else options


# -- values of a config: the one validator of every TOML key (sections of vcjax.config and the
# -- environment components' sections alike)

#: the largest seed of a study: the scenario sampler
#: ([`vcjax.sweep.sample_scenarios`][vcjax.sweep.spec.sample_scenarios])
#: builds its JAX PRNG key from ``jnp.uint32(seed)``, in float64 and float32 mode alike, so
#: every seed of a config or of the Python API lies in ``0 .. SEED_MAX`` (checked by
#: [`as_seed`][vcjax.config.values.as_seed], here and in the sampler: one bound)
SEED_MAX = 2**32 - 1


class ConfigError(ValueError):
    """An invalid configuration (the message names the file, section and key)."""


def as_range(name, v, lo_min=None, positive=False) -> tuple[float, float]:
    """A number (fixed) or ``[lo, hi]`` (sampled uniformly) as ``(lo, hi)``."""
    if isinstance(v, bool) or not isinstance(v, int | float | tuple | list):
        raise ConfigError(f"{name}: expected a number or [lo, hi], got {v!r}")
    if isinstance(v, int | float):
        v = (v, v)
    if len(v) != 2 or any(isinstance(a, bool) or not isinstance(a, int | float) for a in v):
        raise ConfigError(f"{name}: expected a number or a list [lo, hi], got {list(v)!r}")
    lo, hi = float(v[0]), float(v[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ConfigError(f"{name}: expected finite lo <= hi, got [{lo}, {hi}]")
    if lo_min is not None and lo < lo_min:
        raise ConfigError(f"{name}: values must be >= {lo_min}, got [{lo}, {hi}]")
    if positive and lo <= 0:
        raise ConfigError(f"{name}: values must be > 0, got [{lo}, {hi}]")
    return lo, hi


def as_number(name, v, lo=None, lo_open=False, hi=None, hi_open=False) -> float:
    """A finite number within the given bounds."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise ConfigError(f"{name}: expected a finite number, got {v!r}")
    v = float(v)
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ConfigError(f"{name}: expected a value {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise ConfigError(f"{name}: expected a value {'<' if hi_open else '<='} {hi}, got {v}")
    return v


def as_int(name, v, lo) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{name}: expected an integer, got {v!r}")
    if v < lo:
        raise ConfigError(f"{name}: expected an integer >= {lo}, got {v}")
    return v


def as_seed(name, v) -> int:
    """An integer seed in ``0 .. SEED_MAX`` (what the sampler's ``jnp.uint32`` key takes)."""
    if isinstance(v, bool) or not hasattr(v, "__index__"):
        raise ConfigError(f"{name}: expected an integer seed, got {v!r}")
    v = int(v.__index__())
    if not 0 <= v <= SEED_MAX:
        raise ConfigError(
            f"{name}: {v} is outside the seed range 0 .. {SEED_MAX} (2**32 - 1: the scenario "
            "sampler's PRNG key is a 32-bit unsigned integer)"
        )
    return v


def closest(key: str, valid) -> str:
    """`` (did you mean 'x'?)`` for the valid key closest to a mistyped ``key`` (difflib), or
    ``""``."""
    import difflib

    near = difflib.get_close_matches(str(key), [str(v) for v in valid], n=1, cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def unknown_key(section: str, key, valid, note: str = "") -> str:
    """The one message of an unknown key: ``[section] key: unknown key (did you mean 'x'?);
    expected one of [...]`` (``note``: what the valid keys depend on, e.g. ``"for kind
    'line'"``)."""
    valid = list(valid)
    extra = f" {note}" if note else ""
    return f"[{section}] {key}: unknown key{extra}{closest(key, valid)}; expected one of {valid}"


def as_choice(name, v, choices) -> str:
    if v not in choices:
        raise ConfigError(f"{name}: expected one of {list(choices)}, got {v!r}")
    return v


def as_bool(name, v) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"{name}: expected true or false, got {v!r}")
    return v


def as_str(name, v) -> str:
    if not isinstance(v, str):
        raise ConfigError(f"{name}: expected a string, got {type(v).__name__} {v!r}")
    return v


def as_str_list(name, v) -> tuple[str, ...]:
    if not isinstance(v, list | tuple) or not all(isinstance(a, str) for a in v):
        raise ConfigError(f"{name}: expected a list of strings, got {v!r}")
    return tuple(v)


def key(default, type_: str, unit: str = "", doc: str = "", **meta):
    """A section field with its metadata (``choices``, ``lo``/``lo_open``/``hi``/``hi_open``,
    ``aliases``)."""
    return dataclasses.field(
        default=default, metadata={"type": type_, "unit": unit, "doc": doc, **meta}
    )


def check_value(name: str, v, meta) -> Any:
    """``v`` checked against a key's metadata (``ConfigError`` naming ``name``): THE validator of
    every key of every config, the sections of [`vcjax.config`][vcjax.config] (declared with
    [`key`][vcjax._checks.key]) and the environment components' sections (declared with
    [`Key`][vcjax.environment.component.Key]) alike.

    ``meta["type"]``: ``"float"``, ``"int"``, ``"bool"``, ``"str"`` (``choices``), ``"range"``
    (a number or ``[lo, hi]``, as ``(lo, hi)``), ``"sampled"`` (the same, a number kept as a
    number), ``"seed"``, ``"str_list"``, ``"range_list"``; bounds ``lo``/``lo_open``/``hi``/
    ``hi_open`` (a range's ends both within them)."""
    t = meta["type"]
    bounds = {k: meta[k] for k in ("lo", "lo_open", "hi", "hi_open") if k in meta}
    if t == "float":
        return as_number(name, v, **bounds)
    if t == "int":
        return as_int(name, v, meta.get("lo", 0))
    if t == "bool":
        return as_bool(name, v)
    if t == "str":
        v = as_str(name, v)
        return as_choice(name, v, meta["choices"]) if meta.get("choices") else v
    if t in ("range", "sampled"):
        lo, lo_open = meta.get("lo"), meta.get("lo_open", False)
        positive = meta.get("positive", False) or (lo == 0 and lo_open)
        r = as_range(name, v, lo_min=None if positive and lo == 0 else lo, positive=positive)
        if lo_open and lo is not None and lo != 0 and r[0] <= lo:  # ``> 0`` is as_range's
            raise ConfigError(f"{name}: values must be > {lo}, got [{r[0]}, {r[1]}]")
        if "hi" in meta and r[1] > meta["hi"]:
            raise ConfigError(f"{name}: values must be <= {meta['hi']}, got [{r[0]}, {r[1]}]")
        # "sampled" (a component's key): a number stays a number, a list is a (lo, hi) range
        return r[0] if t == "sampled" and isinstance(v, int | float) else r
    if t == "seed":
        return as_seed(name, v)
    if t == "str_list":
        v = as_str_list(name, v)
        if meta.get("unique") and len(set(v)) != len(v):
            raise ConfigError(f"{name}: duplicate names in {list(v)}")
        return v
    if t == "range_list":
        if not isinstance(v, list | tuple):
            raise ConfigError(f"{name}: expected a list, got {v!r}")
        return tuple(as_range(name, r) for r in v)
    raise AssertionError(t)  # pragma: no cover
