"""What a tuning run is, as a frozen object: the sections of a ``vcjax tune`` config
([`TuneConfig`][tuning.spec.TuneConfig]; [`tuning.config`][tuning.config] parses a TOML file into
it, once), their defaults
(``DEFAULTS``) and the description of every key (``KEY_DOCS``, from which the
configuration reference is generated). The keys and their meaning: [`tuning.config`][tuning.config].
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vcjax.config.frozen import FrozenSection, freeze, thaw
from vcjax.config.scenario import ScenarioChoice
from vcjax.config.schema import Current, Disturbance, ModelError, Waves, key

__all__ = [
    "DEFAULTS",
    "KEY_DOCS",
    "TuneConfig",
    "Problem",
    "Weights",
    "ScenarioOffsets",
    "Train",
    "Heldout",
    "Optimizer",
    "Report",
    "Robust",
    "ForceRanges",
    "PlantError",
    "TuneSimulation",
]


_POS = {"lo": 0.0, "lo_open": True}
_NONNEG = {"lo": 0.0}
_OLD = "older spelling of [simulation] "


@dataclasses.dataclass(frozen=True)
class Problem(FrozenSection):
    """``[problem]``: what is tuned and how a rollout is simulated (module docstring)."""

    variant: str = key("", "str", "", "the controller (older spelling of [scenario] controller)")
    tune: tuple[str, ...] = key(
        (), "str_list", "", "gain groups to tune ([] = all of the controller's)", unique=True
    )
    initial_gains: str = key("", "str", "file", 'gains JSON to start from ("" = the defaults)')
    horizon: float = key(80.0, "float", "s", "simulated time (" + _OLD + "horizon)", **_POS)
    dt: float = key(0.1, "float", "s", "integration step (" + _OLD + "dt)", **_POS)
    integrator: str = key("rk4", "str", "", _OLD + "integrator", choices=("euler", "heun", "rk4"))
    timing: str = key("continuous", "str", "", _OLD + "timing", choices=("continuous", "sampled"))
    smooth: bool = key(True, "bool", "", _OLD + "smooth")
    checkpoint: bool = key(
        True,
        "bool",
        "",
        "jax.checkpoint segments of the rollout under reverse mode (recomputed in the backward "
        "pass: a faster and smaller gradient)",
    )
    checkpoint_every: int = key(
        1, "int", "", "steps per checkpointed segment (1: every step, the fastest)", lo=1
    )
    risk: str = key(
        "mean",
        "str",
        "",
        "mean loss over the batch, or cvar (the worst alpha fraction)",
        choices=("mean", "cvar"),
    )
    alpha: float = key(0.2, "float", "", "CVaR level: fraction of worst scenarios", hi=1.0, **_POS)
    log_box: float = key(
        3.0, "float", "", "gains kept within e^log_box of the initial ones (penalty)", **_POS
    )
    box_weight: float = key(10.0, "float", "", "weight of that penalty", **_POS)


@dataclasses.dataclass(frozen=True)
class Weights(FrozenSection):
    """``[weights]``: the loss weights ([`tuning.loss`][tuning.loss])."""

    eps: float = key(1.0, "float", "1/m^2", "weight of the path errors s^2 + e^2", **_NONNEG)
    u_tilde: float = key(1.0, "float", "s^2/m^2", "weight of the speed error", **_NONNEG)
    psi_tilde: float = key(
        1.0, "float", "1/rad^2", "weight of the heading (attitude) error", **_NONNEG
    )
    sat_excess: float = key(
        1.0, "float", "", "weight of the squared command excess over the limits", **_NONNEG
    )
    sat_time: float = key(
        5.0, "float", "", "weight of the (smooth) time over the limits", **_NONNEG
    )
    effort: float = key(
        0.0, "float", "", "weight of the squared commands over their limits", **_NONNEG
    )
    unhealthy: float = key(1000.0, "float", "", "penalty of a run that diverged", **_NONNEG)
    sat_width: float = key(
        0.05, "float", "", "width of the smooth step counting time over the limits", **_POS
    )
    depth: float = key(
        0.0, "float", "1/m^2", "weight of the depth error (3-D loops; e.g. in waves)", **_NONNEG
    )


@dataclasses.dataclass(frozen=True)
class ScenarioOffsets(FrozenSection):
    """``[scenarios]``: the older distribution keys (current speed bound, start offsets)."""

    current_max: float = key(
        1.0, "float", "m/s", "current speed ~ U(0, current_max), any direction", **_NONNEG
    )
    position_offset: float = key(5.0, "float", "m", "initial x, y offsets ~ U(-o, o)", **_NONNEG)
    heading_offset_deg: float = key(
        45.0, "float", "deg", "initial heading offset ~ U(-o, o)", **_NONNEG
    )


@dataclasses.dataclass(frozen=True)
class Train(FrozenSection):
    """``[train]``: the training batch."""

    size: int = key(16, "int", "", "training scenarios", lo=1)
    seed: int = key(0, "seed", "", "seed of the training scenarios")


@dataclasses.dataclass(frozen=True)
class Heldout(FrozenSection):
    """``[heldout]``: the held-out batch (hard-clipped plant unless ``smooth``)."""

    size: int = key(64, "int", "", "held-out scenarios (reported before and after)", lo=1)
    seed: int = key(1001, "seed", "", "seed of the held-out scenarios (must differ from train's)")
    smooth: bool = key(
        False, "bool", "", "smooth saturation on the held-out batch (default: hard clip)"
    )


@dataclasses.dataclass(frozen=True)
class Optimizer(FrozenSection):
    """``[optimizer]`` ([`tuning.optim.tuner_options`][tuning.optim.tuner_options])."""

    name: str = key(
        "lbfgs", "str", "", "lbfgs (zoom line search) or adam", choices=("lbfgs", "adam")
    )
    steps: int = key(40, "int", "", "optimiser iterations", lo=1)
    learning_rate: float = key(0.05, "float", "", "Adam's step size", **_POS)
    memory_size: int = key(10, "int", "", "L-BFGS history length", lo=1)
    max_linesearch_steps: int = key(15, "int", "", "L-BFGS line-search evaluations per step", lo=1)
    grad_mode: str = key(
        "reverse",
        "str",
        "",
        "reverse mode, or forward (jax.jacfwd) for few gains",
        choices=("reverse", "forward"),
    )
    max_bad_steps: int = key(5, "int", "", "non-finite steps tolerated before aborting", lo=1)
    grad_tol: float = key(
        1e-8, "float", "", "stop when the gradient norm falls below this", **_NONNEG
    )


@dataclasses.dataclass(frozen=True)
class Report(FrozenSection):
    """``[report]``."""

    plot_scenarios: int = key(
        4, "int", "", "held-out scenarios drawn in the before/after figures", lo=0
    )


#: spellings of the tuning loss as a metric (``[robust] metric``, ``vcjax falsify --metric loss``)
LOSS_NAMES = ("tuning_loss", "loss")


@dataclasses.dataclass(frozen=True)
class Robust(FrozenSection):
    """``[robust]`` (optional; its presence switches robust tuning on,
    [`tuning.robust`][tuning.robust]): every ``adversarial_every`` steps, a gradient search
    of the tune's own scenario ranges for the worst scenarios against the current gains; the
    ``adversarial_count`` worst replace the adversarial slot of the training batch."""

    adversarial_every: int = key(5, "int", "", "optimiser steps between two searches (K)", lo=1)
    adversarial_count: int = key(
        4, "int", "", "worst scenarios put in the training batch by each search", lo=1
    )
    budget: int = key(10, "int", "", "ascent steps of each search (one rollout per start)", lo=1)
    starts: int = key(8, "int", "", "starts of each search (>= adversarial_count)", lo=1)
    step_size: float = key(0.1, "float", "", "Adam step of the search in the unit box", **_POS)
    metric: str = key(
        "tuning_loss",
        "str",
        "",
        "what is maximised: tuning_loss (the [weights] loss) or a sweep metric",
    )
    seed: int = key(7, "seed", "", "seed of the searches (round r: scenarios r x starts on)")
    compare: bool = key(
        False, "bool", "", "also tune without [robust] in the same run (summary: robust.nominal)"
    )
    check_starts: int = key(16, "int", "", "starts of the independent worst-case search", lo=1)
    check_budget: int = key(20, "int", "", "ascent steps of that search", lo=1)
    check_seed: int = key(1007, "seed", "", "its seed (other than the training searches')")


@dataclasses.dataclass(frozen=True)
class TuneSimulation(FrozenSection):
    """What ``[simulation]`` adds to ``[problem]``: the desired-speed range [m/s]."""

    u_d: tuple[float, float] | None = None


#: the older names of the shared sections' classes (one declaration: vcjax.config.schema)
ForceRanges = Disturbance
PlantError = ModelError


#: the sections of [`TuneConfig`][tuning.spec.TuneConfig] read from a table of their own name (and
#: their keys)
_SECTIONS = {
    "problem": Problem,
    "weights": Weights,
    "scenarios": ScenarioOffsets,
    "train": Train,
    "heldout": Heldout,
    "optimizer": Optimizer,
    "report": Report,
    "disturbance": ForceRanges,
    "model_error": PlantError,
}


@dataclasses.dataclass(frozen=True)
class TuneConfig(FrozenSection):
    """A tuning config, parsed once (``load_config``), frozen and hashable.

    Attributes are the sections (``cfg.problem.horizon``; ``cfg["problem"]["horizon"]`` reads
    the same); the shared ones as they are parsed: ``current``
    (`Current`, the ``[scenarios] current_max`` shorthand written
    out), ``waves`` (`Waves` or ``None``), ``disturbance``,
    ``model_error``; ``initial`` the ``[initial]`` ranges as ``(key, range)`` pairs,
    ``environment`` the sections of [`vcjax.environment`][vcjax.environment] components
    (``((section, table), ...)``, as a sweep's) and ``scenario`` the parsed ``[scenario]``
    ([`ScenarioChoice`][vcjax.config.scenario.ScenarioChoice]). Read as a mapping, ``current``,
    ``waves``, ``initial``, ``environment`` and ``scenario`` are plain dicts; ``to_dict`` is what
    ``run.json`` records and ``from_dict`` reads it back.
    """

    problem: Problem = Problem()
    weights: Weights = Weights()
    scenarios: ScenarioOffsets = ScenarioOffsets()
    train: Train = Train()
    heldout: Heldout = Heldout()
    optimizer: Optimizer = Optimizer()
    report: Report = Report()
    disturbance: Disturbance = Disturbance()
    model_error: ModelError = ModelError()
    simulation: TuneSimulation = TuneSimulation()
    current: Current = Current(speed=(0.0, 1.0), direction_deg=(0.0, 360.0))
    waves: Waves | None = None
    initial: tuple[tuple[str, tuple[float, float]], ...] = ()
    environment: tuple = ()
    scenario: ScenarioChoice = ScenarioChoice()
    robust: Robust | None = None  # [robust] given: robust tuning (tuning.robust)

    def __getitem__(self, key: str) -> Any:
        if key in _PLAIN:
            return self.to_dict()[key]
        return super().__getitem__(key)

    def to_dict(self) -> dict:
        out = {k: thaw(getattr(self, k)) for k in self._keys() if k not in _PLAIN}
        out["current"] = _plain(self.current)
        out["waves"] = None if self.waves is None else _plain(self.waves)
        out["initial"] = {k: thaw(v) for k, v in self.initial}
        out["environment"] = {s: {k: thaw(v) for k, v in t} for s, t in self.environment}
        out["scenario"] = self.scenario.to_dict()
        if self.robust is None:  # recorded only where given
            out.pop("robust")
        return out

    @classmethod
    def from_dict(cls, d) -> TuneConfig:
        d = dict(d)
        waves = d.pop("waves", None)
        robust = d.pop("robust", None)
        plain = {
            "current": Current(**{k: freeze(v) for k, v in d.pop("current", {}).items()}),
            "waves": None if waves is None else Waves(**{k: freeze(v) for k, v in waves.items()}),
            "initial": freeze(dict(d.pop("initial", {}))),
            "environment": freeze(dict(d.pop("environment", {}))),
            "scenario": ScenarioChoice.from_dict(d.pop("scenario", ScenarioChoice().to_dict())),
            "robust": None if robust is None else Robust.from_dict(robust),
        }
        return dataclasses.replace(super().from_dict(d), **plain)


def _plain(section) -> dict:
    return {f.name: thaw(getattr(section, f.name)) for f in dataclasses.fields(section)}


#: the fields of [`TuneConfig`][tuning.spec.TuneConfig] that read as plain dicts
_PLAIN = ("current", "waves", "initial", "environment", "scenario")

#: section -> key -> default (lists where the frozen sections hold tuples); the configuration
#: reference is generated from it
DEFAULTS: dict[str, dict[str, Any]] = {name: cls().to_dict() for name, cls in _SECTIONS.items()}
#: the optional sections (parsed only where given; their presence is a switch)
_OPTIONAL = {"robust": Robust}
DEFAULTS |= {name: cls().to_dict() for name, cls in _OPTIONAL.items()}


#: (section, key) -> (unit, description) of the tune-only keys, read from the sections'
#: declarations (the shared sections are described in [`vcjax.config.schema`][vcjax.config.schema]);
#: the
#: configuration reference is generated from it
KEY_DOCS: dict[tuple[str, str], tuple[str, str]] = {
    (name, f.name): (f.metadata["unit"], f.metadata["doc"])
    for name, cls in {**_SECTIONS, **_OPTIONAL}.items()
    for f in dataclasses.fields(cls)
}
