"""Worst-case scenario search (``vcjax falsify``): which current, sea and start within an
envelope make a controller's metric largest.

* :mod:`vcjax.search.envelope`: :class:`Envelope` (parameter names in config units -> boxes),
  :class:`Setting` (what is held fixed), :func:`scenario_from` (a parameter vector -> the traced
  scenario; the one place that knows how a scenario is built);
* :mod:`vcjax.search.core`: :func:`falsify` (multi-start projected gradient ascent, with random
  sampling as its baseline), :func:`evaluate` (metrics of given parameters: a replay);
* :mod:`vcjax.search.config`: ``vcjax falsify CONFIG``: the TOML file, outputs, replay;
* :mod:`vcjax.search.figures`: the worst trajectory, worst metric found vs rollouts.
"""

from vcjax.search.core import ALIASES, FalsifyResult, evaluate, falsify, metric_name
from vcjax.search.envelope import (
    Envelope,
    Setting,
    envelope_from_spec,
    make_setting,
    scenario_from,
    setting_from_spec,
)

__all__ = [
    "ALIASES",
    "Envelope",
    "FalsifyResult",
    "Setting",
    "envelope_from_spec",
    "evaluate",
    "falsify",
    "make_setting",
    "metric_name",
    "scenario_from",
    "setting_from_spec",
]
