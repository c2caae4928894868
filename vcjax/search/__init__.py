"""Worst-case scenario search (``vcjax falsify``): which current, sea and start within an
envelope make a controller's metric largest.

* [`vcjax.search.envelope`][vcjax.search.envelope]: [`Envelope`][vcjax.search.envelope.Envelope]
(parameter names in config units -> boxes),
  [`Setting`][vcjax.search.envelope.Setting] (what is held fixed),
  [`scenario_from`][vcjax.search.envelope.scenario_from] (a parameter vector -> the traced
  scenario; the one place that knows how a scenario is built);
* [`vcjax.search.core`][vcjax.search.core]: [`falsify`][vcjax.search.core.falsify] (multi-start
projected gradient ascent, with random
  sampling as its baseline), [`evaluate`][vcjax.search.core.evaluate] (metrics of given parameters:
  a replay);
* [`vcjax.search.config`][vcjax.search.config]: ``vcjax falsify CONFIG``: the TOML file, outputs,
replay;
* [`vcjax.search.figures`][vcjax.search.figures]: the worst trajectory, worst metric found vs
rollouts.
"""

from vcjax.search.core import (
    ALIASES,
    FalsifyOptions,
    FalsifyResult,
    SegmentMetric,
    evaluate,
    falsify,
    gradient_mode,
    metric_name,
)
from vcjax.search.envelope import (
    Envelope,
    Setting,
    SettingOptions,
    envelope_from_scenario,
    envelope_from_spec,
    make_setting,
    scenario_from,
    setting_from_spec,
)

__all__ = [
    "ALIASES",
    "Envelope",
    "FalsifyOptions",
    "gradient_mode",
    "FalsifyResult",
    "SegmentMetric",
    "Setting",
    "SettingOptions",
    "envelope_from_scenario",
    "envelope_from_spec",
    "evaluate",
    "falsify",
    "make_setting",
    "metric_name",
    "scenario_from",
    "setting_from_spec",
]
