"""Parameter and gains NamedTuples by name: dotted parameter names, lookup and replacement;
the one gains-JSON reader and writer; the one [`GainSpec`][vcjax.loops.types.GainSpec] builder."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from vcjax.loops.types import GainSpec

__all__ = [
    "param_names",
    "get_param",
    "replace_params",
    "gains_to_json",
    "gains_from_json",
    "gain_spec",
]


def param_names(params, prefix: str = "") -> tuple[str, ...]:
    """Names of every array field of a (nested) parameter NamedTuple, dotted for nesting
    (``"mass"``, ``"body.W"``)."""
    out = []
    for k, v in params._asdict().items():
        if hasattr(v, "_asdict"):
            out += param_names(v, f"{prefix}{k}.")
        else:
            out.append(prefix + k)
    return tuple(out)


def get_param(params, name: str):
    for part in name.split("."):
        params = getattr(params, part)
    return params


def replace_params(params, values: dict):
    """``params`` with the (dotted) fields of ``values`` replaced (pure; traced values ok)."""
    nested: dict[str, dict] = {}
    flat = {}
    for k, v in values.items():
        head, _, rest = k.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = v
        else:
            flat[head] = v
    for head, sub in nested.items():
        flat[head] = replace_params(getattr(params, head), sub)
    return params._replace(**flat)


# --------------------------------------------------------------------------------------------
# Gains <-> JSON (any NamedTuple of arrays / NamedTuples)
# --------------------------------------------------------------------------------------------


def gains_to_json(gains) -> dict:
    """Plain-JSON form of a gains NamedTuple (nested NamedTuples become nested objects)."""
    out = {}
    for k, v in gains._asdict().items():
        out[k] = gains_to_json(v) if hasattr(v, "_asdict") else np.asarray(v).tolist()
    return out


def gains_from_json(d, default, where: str = "gains file", validate=None):
    """A gains NamedTuple like ``default`` with the entries of ``d`` (the one gains-JSON reader).

    Missing entries keep the default; nested NamedTuples are nested objects (sections). Raises
    ``ValueError`` naming the entry for a non-object, an unknown entry or section, a wrong
    shape, a non-numeric or a non-finite value. ``validate(gains) -> gains`` (a law's eager
    checks, e.g. positivity) runs on the result; a ``TypeError`` it raises becomes a
    ``ValueError``.
    """
    gains = _read(d, default, where)
    if validate is None:
        return gains
    try:
        return validate(gains)
    except TypeError as err:
        raise ValueError(f"{where}: {err}") from None


def _read(d, default, where):
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object, got {type(d).__name__}")
    nested = any(hasattr(v, "_asdict") for v in default)
    unknown = sorted(set(d) - set(default._fields))
    if unknown:
        kind = "sections" if nested else "entries"
        raise ValueError(f"{where}: unknown {kind} {unknown}; expected {list(default._fields)}")
    vals = {}
    for k, v in d.items():
        ref = getattr(default, k)
        if hasattr(ref, "_asdict"):
            if not isinstance(v, dict):
                raise ValueError(
                    f"{where}: section '{k}' must be an object of gains, got {type(v).__name__}"
                )
            vals[k] = _read(v, ref, f"{where}: {k}")
            continue
        a = np.asarray(v)
        if a.shape != np.shape(ref):
            raise ValueError(f"{where}: {k}: expected shape {np.shape(ref)}, got {a.shape}")
        if a.dtype.kind not in "biuf":
            raise ValueError(f"{where}: {k}: expected a numeric array, got {v!r}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{where}: {k}: not finite: {v!r}")
        vals[k] = jnp.asarray(a.astype(float), dtype=jnp.asarray(ref).dtype)
    return default._replace(**vals)


def gain_spec(name: str, field: str | None = None, size: int = 1, index=None, bound=None):
    """The [`GainSpec`][vcjax.loops.types.GainSpec] of the gains field ``field`` (dotted for nested
    NamedTuples; default ``name``), or of its entries ``index`` (a ``slice``).

    ``size`` entries (a slice's length when ``index`` is given); a ``size``-1 group of a ``()``
    field is read as (1,) and written back as ``()``. ``bound``: see ``GainSpec``.
    """
    field = name if field is None else field
    if index is not None:
        size = len(range(*index.indices(1 << 30)))

    def get(g):
        v = get_param(g, field)
        return jnp.atleast_1d(v) if index is None else v[index]

    def put(g, value):
        if index is not None:
            value = get_param(g, field).at[index].set(value)
        elif size == 1 and jnp.ndim(get_param(g, field)) == 0:
            value = value[0]
        return replace_params(g, {field: value})

    return GainSpec(name, size, get, put, bound)
