"""Compatibility re-exports of what ``vcjax.loops.base`` held before it was split by job
(:mod:`~vcjax.loops.types`, :mod:`~vcjax.loops.loop`, :mod:`~vcjax.loops.law`,
:mod:`~vcjax.loops.disturbances`, :mod:`~vcjax.loops.params`, :mod:`~vcjax.loops.geometry`).
New code imports from :mod:`vcjax.loops`."""

from vcjax.loops.disturbances import (
    DisturbanceParams,
    Disturbances,
    gauss_markov_params,
    simulate,
)
from vcjax.loops.geometry import path_polyline, start_parameter
from vcjax.loops.loop import Loop
from vcjax.loops.params import (
    gains_from_json,
    gains_to_json,
    get_param,
    param_names,
    replace_params,
)
from vcjax.loops.types import GainSpec, Scenario, Signals

__all__ = [
    "Scenario",
    "GainSpec",
    "Signals",
    "Loop",
    "Disturbances",
    "DisturbanceParams",
    "gauss_markov_params",
    "simulate",
    "start_parameter",
    "path_polyline",
    "param_names",
    "get_param",
    "replace_params",
    "gains_to_json",
    "gains_from_json",
]
