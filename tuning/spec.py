"""What a tuning run is, as a frozen object: the sections of a ``vcjax tune`` config
(:class:`TuneConfig`; :mod:`tuning.config` parses a TOML file into it, once), their defaults
(:data:`DEFAULTS`) and the description of every key (:data:`KEY_DOCS`, from which the
configuration reference is generated). The keys and their meaning: :mod:`tuning.config`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vcjax.config.frozen import FrozenSection, freeze, thaw
from vcjax.config.scenario import ScenarioChoice

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
    "ForceRanges",
    "PlantError",
    "TuneSimulation",
]


@dataclasses.dataclass(frozen=True)
class Problem(FrozenSection):
    """``[problem]``: what is tuned and how a rollout is simulated (module docstring)."""

    variant: str = ""
    tune: tuple[str, ...] = ()
    initial_gains: str = ""
    horizon: float = 80.0
    dt: float = 0.1
    integrator: str = "rk4"
    timing: str = "continuous"
    smooth: bool = True
    checkpoint: bool = False
    checkpoint_every: int = 10
    edd: str = "paper"
    risk: str = "mean"
    alpha: float = 0.2
    log_box: float = 3.0
    box_weight: float = 10.0


@dataclasses.dataclass(frozen=True)
class Weights(FrozenSection):
    """``[weights]``: the loss weights (:mod:`tuning.loss`)."""

    eps: float = 1.0
    u_tilde: float = 1.0
    psi_tilde: float = 1.0
    sat_excess: float = 1.0
    sat_time: float = 5.0
    effort: float = 0.0
    unhealthy: float = 1000.0
    sat_width: float = 0.05
    depth: float = 0.0


@dataclasses.dataclass(frozen=True)
class ScenarioOffsets(FrozenSection):
    """``[scenarios]``: the older distribution keys (current speed bound, start offsets)."""

    current_max: float = 1.0
    position_offset: float = 5.0
    heading_offset_deg: float = 45.0


@dataclasses.dataclass(frozen=True)
class Train(FrozenSection):
    """``[train]``: the training batch."""

    size: int = 16
    seed: int = 0


@dataclasses.dataclass(frozen=True)
class Heldout(FrozenSection):
    """``[heldout]``: the held-out batch (hard-clipped plant unless ``smooth``)."""

    size: int = 64
    seed: int = 1001
    smooth: bool = False


@dataclasses.dataclass(frozen=True)
class Optimizer(FrozenSection):
    """``[optimizer]`` (:func:`tuning.optim.tuner_options`)."""

    name: str = "lbfgs"
    steps: int = 40
    learning_rate: float = 0.05
    memory_size: int = 10
    max_linesearch_steps: int = 15
    grad_mode: str = "reverse"
    max_bad_steps: int = 5
    grad_tol: float = 1e-8


@dataclasses.dataclass(frozen=True)
class Report(FrozenSection):
    """``[report]``."""

    plot_scenarios: int = 4


@dataclasses.dataclass(frozen=True)
class ForceRanges(FrozenSection):
    """``[disturbance]``: one ``(lo, hi)`` range per generalised force component."""

    force: tuple[tuple[float, float], ...] = ()


@dataclasses.dataclass(frozen=True)
class PlantError(FrozenSection):
    """``[model_error]``: plant parameters scaled by ``1 + relative U(-1, 1)``."""

    relative: float = 0.0
    fields: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class TuneSimulation(FrozenSection):
    """What ``[simulation]`` adds to ``[problem]``: the desired-speed range [m/s]."""

    u_d: tuple[float, float] | None = None


#: the sections of :class:`TuneConfig` read from a table of their own name (and their keys)
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
    """A tuning config, parsed once (:func:`load_config`), frozen and hashable.

    Attributes are the sections (``cfg.problem.horizon``; ``cfg["problem"]["horizon"]`` reads
    the same); ``scenario`` is the parsed ``[scenario]``
    (:class:`~vcjax.config.scenario.ScenarioChoice`), ``initial`` the ``[initial]`` ranges and
    ``current`` the ``[current]`` keys given, as ``(key, value)`` pairs. Read as a mapping,
    ``current``, ``initial`` and ``scenario`` are plain dicts (as the older dict result had
    them); :meth:`to_dict` is what ``run.json`` records and :meth:`from_dict` reads it back.
    """

    problem: Problem = Problem()
    weights: Weights = Weights()
    scenarios: ScenarioOffsets = ScenarioOffsets()
    train: Train = Train()
    heldout: Heldout = Heldout()
    optimizer: Optimizer = Optimizer()
    report: Report = Report()
    disturbance: ForceRanges = ForceRanges()
    model_error: PlantError = PlantError()
    simulation: TuneSimulation = TuneSimulation()
    current: tuple[tuple[str, Any], ...] = ()
    waves: tuple[tuple[str, Any], ...] | None = None
    initial: tuple[tuple[str, tuple[float, float]], ...] = ()
    scenario: ScenarioChoice = ScenarioChoice()

    def __getitem__(self, key: str) -> Any:
        if key in _PLAIN:
            return self.to_dict()[key]
        return super().__getitem__(key)

    def to_dict(self) -> dict:
        out = {k: thaw(getattr(self, k)) for k in self._keys() if k not in _PLAIN}
        out["current"] = {k: thaw(v) for k, v in self.current}
        out["waves"] = None if self.waves is None else {k: thaw(v) for k, v in self.waves}
        out["initial"] = {k: thaw(v) for k, v in self.initial}
        out["scenario"] = self.scenario.to_dict()
        return out

    @classmethod
    def from_dict(cls, d) -> TuneConfig:
        d = dict(d)
        waves = d.pop("waves", None)
        plain = {
            "current": freeze(dict(d.pop("current", {}))),
            "waves": None if waves is None else freeze(dict(waves)),
            "initial": freeze(dict(d.pop("initial", {}))),
            "scenario": ScenarioChoice.from_dict(d.pop("scenario", ScenarioChoice().to_dict())),
        }
        return dataclasses.replace(super().from_dict(d), **plain)


#: the fields of :class:`TuneConfig` that read as plain dicts
_PLAIN = ("current", "waves", "initial", "scenario")

#: section -> key -> default (lists where the frozen sections hold tuples); the configuration
#: reference is generated from it
DEFAULTS: dict[str, dict[str, Any]] = {name: cls().to_dict() for name, cls in _SECTIONS.items()}


#: (section, key) -> (unit, description) of the tune-only keys (the shared sections are
#: described in :mod:`vcjax.config.schema`); the configuration reference is generated from it
KEY_DOCS: dict[tuple[str, str], tuple[str, str]] = {
    ("problem", "variant"): ("", "the controller (older spelling of [scenario] controller)"),
    ("problem", "tune"): ("", "gain groups to tune ([] = all of the controller's)"),
    ("problem", "initial_gains"): ("file", 'gains JSON to start from ("" = the defaults)'),
    ("problem", "horizon"): ("s", "simulated time (older spelling of [simulation] horizon)"),
    ("problem", "dt"): ("s", "integration step (older spelling of [simulation] dt)"),
    ("problem", "integrator"): ("", "older spelling of [simulation] integrator"),
    ("problem", "timing"): ("", "older spelling of [simulation] timing"),
    ("problem", "smooth"): ("", "older spelling of [simulation] smooth"),
    ("problem", "checkpoint"): ("", "jax.checkpoint segments of the rollout under reverse mode"),
    ("problem", "checkpoint_every"): ("", "steps per checkpointed segment"),
    ("problem", "edd"): ("", "VCM e_ddot mode: paper or implied"),
    ("problem", "risk"): ("", "mean loss over the batch, or cvar (the worst alpha fraction)"),
    ("problem", "alpha"): ("", "CVaR level: fraction of worst scenarios"),
    ("problem", "log_box"): ("", "gains kept within e^log_box of the initial ones (penalty)"),
    ("problem", "box_weight"): ("", "weight of that penalty"),
    ("weights", "eps"): ("1/m^2", "weight of the path errors s^2 + e^2"),
    ("weights", "u_tilde"): ("s^2/m^2", "weight of the speed error"),
    ("weights", "psi_tilde"): ("1/rad^2", "weight of the heading (attitude) error"),
    ("weights", "sat_excess"): ("", "weight of the squared command excess over the limits"),
    ("weights", "sat_time"): ("", "weight of the (smooth) time over the limits"),
    ("weights", "effort"): ("", "weight of the squared commands over their limits"),
    ("weights", "unhealthy"): ("", "penalty of a run that diverged"),
    ("weights", "sat_width"): ("", "width of the smooth step counting time over the limits"),
    ("weights", "depth"): ("1/m^2", "weight of the depth error (3-D loops; e.g. in waves)"),
    ("scenarios", "current_max"): ("m/s", "current speed ~ U(0, current_max), any direction"),
    ("scenarios", "position_offset"): ("m", "initial x, y offsets ~ U(-o, o)"),
    ("scenarios", "heading_offset_deg"): ("deg", "initial heading offset ~ U(-o, o)"),
    ("train", "size"): ("", "training scenarios"),
    ("train", "seed"): ("", "seed of the training scenarios"),
    ("heldout", "size"): ("", "held-out scenarios (reported before and after)"),
    ("heldout", "seed"): ("", "seed of the held-out scenarios (must differ from train's)"),
    ("heldout", "smooth"): ("", "smooth saturation on the held-out batch (default: hard clip)"),
    ("optimizer", "name"): ("", "lbfgs (zoom line search) or adam"),
    ("optimizer", "steps"): ("", "optimiser iterations"),
    ("optimizer", "learning_rate"): ("", "Adam's step size"),
    ("optimizer", "memory_size"): ("", "L-BFGS history length"),
    ("optimizer", "max_linesearch_steps"): ("", "L-BFGS line-search evaluations per step"),
    ("optimizer", "grad_mode"): ("", "reverse mode, or forward (jax.jacfwd) for few gains"),
    ("optimizer", "max_bad_steps"): ("", "non-finite steps tolerated before aborting"),
    ("optimizer", "grad_tol"): ("", "stop when the gradient norm falls below this"),
    ("report", "plot_scenarios"): ("", "held-out scenarios drawn in the before/after figures"),
    ("disturbance", "force"): ("N, N m", "one range per generalised force component"),
    ("model_error", "relative"): ("", "plant parameters scaled by 1 + relative U(-1, 1)"),
    ("model_error", "fields"): ("", "the parameters perturbed ([] = the vehicle's default set)"),
}
