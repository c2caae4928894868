"""Eager (pre-compilation) input validation.

Every public constructor of parameters calls these in plain Python, so a user sees a ``ValueError``
that names the offending field before anything is traced or compiled. Inside ``jit`` the arrays
are tracers and the checks are skipped (health is then reported as data by the rollout).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

__all__ = [
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
