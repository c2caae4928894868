"""Sweep results as a labelled ``xarray.Dataset`` (optional: ``pip install "vcjax[xarray]"``).

[`to_xarray`][vcjax.sweep.labelled.to_xarray] (also
[`SweepResult.to_xarray`][vcjax.sweep.results.SweepResult.to_xarray]) gives one dataset with the
dimensions
``variant`` x ``scenario`` (coordinate: the scenario numbers), the sampled inputs as variables
over ``scenario`` (vector inputs get a labelled component dimension), every metric and health
flag as a variable over ``variant`` x ``scenario``, the decimated traces over ``variant`` x
``scenario`` x ``time``, units as ``units`` attributes, and the study (its spec as JSON, seed,
sizes) as dataset attributes. [`write_netcdf`][vcjax.sweep.labelled.write_netcdf] writes it as
``results.nc`` (netCDF via scipy,
so no compiled netCDF library is needed; booleans are stored as int8 with a ``flag`` attribute).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from vcjax.metrics import FLAGS, METRICS
from vcjax.runtime.outputs import write_atomic

__all__ = ["to_xarray", "write_netcdf", "METRIC_UNITS", "INPUT_UNITS"]

#: Units of the loop-independent metrics (``max_abs_<actuator>`` ones are derived from the name).
METRIC_UNITS = {
    "ss_abs_e": "m",
    "ss_abs_s": "m",
    "ss_abs_u_err": "m/s",
    "iae_e": "m s",
    "max_abs_e": "m",
    "rms_along_track_s": "m",
    "rms_cross_track_e": "m",
    "rms_dist_3d": "m",
    "max_dist_3d": "m",
    "rms_depth_err": "m",
    "sat_fraction": "1",
}
#: Units and components of the sampled inputs ([`MCScenario`][vcjax.sweep.spec.MCScenario] fields).
INPUT_UNITS = {
    "u_d": ("m/s", None),
    "current_speed": ("m/s", None),
    "current_direction": ("rad", None),
    "current": ("m/s", ("north", "east", "down")),
    "current_sigma": ("m/s", None),
    "current_tau": ("s", None),
    "current_max_speed": ("m/s", None),
    "model_factors": ("1", None),
    "noise_std": ("SI (per channel)", None),
    "disturbance": ("N, N m (body frame)", None),
    "eta0": ("m, rad", None),
    "nu0": ("m/s, rad/s", None),
    "wave_hs": ("m", None),
    "wave_tp": ("s", None),
    "wave_direction_deg": ("deg", None),
    "wave_origin_depth": ("m", None),
}
#: Sampled fields left out: the scenario number is the ``scenario`` coordinate, and the PRNG key
#: follows from it (``fold_in(PRNGKey(seed), index)``).
_SKIP = ("index", "key")
_ACT_UNITS = {"tau_u": "N", "thrust": "N"}


def _xr():
    try:
        import xarray
    except ImportError:
        raise ImportError(
            'SweepResult.to_xarray needs xarray: pip install "vcjax[xarray]"'
        ) from None
    return xarray


def _metric_units(name: str) -> str | None:
    if name in METRIC_UNITS:
        return METRIC_UNITS[name]
    if name.startswith("max_abs_"):
        act = name[len("max_abs_") :]
        if act.endswith("_deg"):
            return "deg"
        return _ACT_UNITS.get(act)
    return None


def to_xarray(result):
    """The [`SweepResult`][vcjax.sweep.results.SweepResult] as an ``xarray.Dataset`` (see the
    module)."""
    from vcjax.sweep.spec import spec_to_dict

    xr = _xr()
    spec = result.spec
    variants = list(result.metrics)
    coords = {"variant": variants, "scenario": np.asarray(result.index)}
    data = {}
    empty: list[str] = []
    fields = spec.scenario.fields_for(spec.loop(spec.variants[0]))
    for k, v in result.scenarios.items():
        if k in _SKIP:
            continue
        v = np.asarray(v)
        if 0 in v.shape[1:]:  # nothing sampled (e.g. no sensor noise): no zero-length dimension
            empty.append(k)  # (netCDF 3 would read it as a second, invalid record dimension)
            continue
        units, labels = INPUT_UNITS.get(k, (None, None))
        attrs = {"long_name": f"sampled input {k}"}
        if units:
            attrs["units"] = units
        if v.ndim == 1:
            data[k] = (("scenario",), v, attrs)
            continue
        dim = "model_field" if k == "model_factors" else f"{k}_component"
        if k == "model_factors":
            labels = tuple(fields)
        if labels is not None and len(labels) == v.shape[1]:
            coords[dim] = list(labels)
        data[k] = (("scenario", dim, *(f"{k}_{i}" for i in range(2, v.ndim))), v, attrs)
    names = [n for n in result.metrics[variants[0]] if n not in FLAGS]
    for name in names:
        attrs = {"long_name": f"metric {name}"}
        if (u := _metric_units(name)) is not None:
            attrs["units"] = u
        stack = np.stack([np.asarray(result.metrics[v][name]) for v in variants])
        data[name] = (("variant", "scenario"), stack, attrs)
    for name in FLAGS:
        if name in result.metrics[variants[0]]:
            stack = np.stack([np.asarray(result.metrics[v][name], dtype=bool) for v in variants])
            data[name] = (("variant", "scenario"), stack, {"long_name": f"health flag {name}"})
    if result.trace_t.size and result.traces.get(variants[0]):
        coords["time"] = ("time", np.asarray(result.trace_t), {"units": "s"})
        e = np.stack([np.asarray(result.traces[v]["e"]) for v in variants])
        data["trace_e"] = (
            ("variant", "scenario", "time"),
            e,
            {"units": "m", "long_name": "cross-track error e (decimated)"},
        )
        xy = np.stack([np.asarray(result.traces[v]["xy"]) for v in variants])
        coords["horizontal"] = ["north", "east"]
        data["trace_xy"] = (
            ("variant", "scenario", "time", "horizontal"),
            xy,
            {"units": "m", "long_name": "horizontal position (decimated)"},
        )
    attrs = {
        "title": "vcjax sweep",
        "spec_json": json.dumps(spec_to_dict(spec)),
        "seed": int(spec.seed),
        "num_scenarios": int(spec.num_scenarios),
        "horizon_s": float(spec.horizon),
        "dt_s": float(spec.dt),
        "steady_state_tail": float(spec.tail),
        "wall_s": float(result.wall_s),
        "metrics": " ".join(METRICS),
    }
    if empty:
        attrs["empty_inputs"] = " ".join(empty)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def write_netcdf(result, path) -> Path:
    """Write [`to_xarray`][vcjax.sweep.labelled.to_xarray] of ``result`` to ``path`` (netCDF 3 via
    scipy's writer)."""
    ds = to_xarray(result)
    for name in list(ds.data_vars):
        if ds[name].dtype == bool:
            ds[name] = ds[name].astype(np.int8)
            ds[name].attrs["flag"] = "1 = true"
    # atomically (a temporary file beside it, then renamed): a killed run leaves the old file
    # or none, never half a file
    return write_atomic(Path(path), lambda tmp: ds.to_netcdf(tmp, engine="scipy"))
