"""The registry of experiment presets that ``vcjax simulate NAME`` runs (and ``vcjax demo``).

Each :class:`Experiment` names the module that implements it (imported on use, after the CLI has
chosen the precision) and the command-line options it applies. Every experiment takes the same
common options -- ``--gains FILE`` (the gains JSON ``vcjax tune`` writes for its vehicle),
``--current V_N V_E``, ``--horizon``, ``--dt``, ``--out`` -- and only the extra ones it lists in
:attr:`Experiment.options`; the CLI refuses any other option with exit status 2 and a one-line
message naming it (it is never silently ignored and recorded as if applied).

An experiment module provides:

* ``load_gains(d: dict, **options) -> gains``: the gains of a gains-JSON object (missing
  entries: the defaults), validated (``ValueError`` naming the entry);
* ``run_experiment(out, gains, *, horizon, dt, current, progress, **options) -> dict`` with
  ``"metrics"`` (what ``metrics.json`` holds), ``"files"``, ``"printed"`` (flat metrics per run
  for the console) and ``"unhealthy"`` (``{run name: one-line reason}``).

``waves`` and ``wave_seed`` are the options of the experiments whose loops feel a sea
(``remus100``, ``sim2``): ``--waves HS TP DIR_DEG`` puts every run in one random JONSWAP sea
(:func:`vcjax.environment.waves.sea_state`, 64 components, long-crested) drawn from
``PRNGKey(--wave-seed)`` (default 0); the others refuse them.

The experiments: ``sim1`` (Simulation 1 of the paper: INFANTE-class on a line, every
controller), ``sim2`` (Simulation 2: ODIN-class on a helix, both actuation modes), ``remus100``
(a 3-D lawnmower survey of the PVS REMUS 100 under a cross current, every controller), ``arm``
(the two-link arm drawing a circle with the generic engine; ``vcjax demo``).
"""

from __future__ import annotations

import dataclasses
import importlib
from types import ModuleType

__all__ = ["Experiment", "EXPERIMENTS", "get", "names"]


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One preset of ``vcjax simulate``.

    Attributes:
        name: what ``vcjax simulate NAME`` calls it.
        summary: one line for ``--help``.
        module: the module implementing it (module docstring).
        horizon, dt: default simulated time and step [s].
        current: default ocean current ``(north, east)`` [m/s]; ``None``: the experiment takes
            no ``--current``.
        options: its own command-line options (attribute names of the parsed arguments, e.g.
            ``"edd"``), with their defaults.
        gains: whether it takes ``--gains``.
    """

    name: str
    summary: str
    module: str
    horizon: float
    dt: float
    current: tuple[float, float] | None = None
    options: tuple[tuple[str, str | None], ...] = ()
    gains: bool = True

    def load(self) -> ModuleType:
        """The implementing module (imported now)."""
        return importlib.import_module(self.module)


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            "sim1",
            "Simulation 1 (INFANTE-class, line, Figs. 4-5), every controller",
            "vcjax.experiments.sim1",
            horizon=150.0,
            dt=0.05,
            current=(0.0, 0.5),
            options=(("edd", "paper"), ("timing", "continuous"), ("diverge_e", None)),
        ),
        Experiment(
            "sim2",
            "Simulation 2 (ODIN-class, helix, Figs. 6-7), both actuation modes",
            "vcjax.experiments.sim2",
            horizon=300.0,
            dt=0.05,
            options=(
                ("actuation", "underactuated"),
                ("diverge_e", None),
                ("waves", None),
                ("wave_seed", 0),
            ),
        ),
        Experiment(
            "remus100",
            "3-D survey mission of the PVS REMUS 100 under a cross current, every controller",
            "vcjax.experiments.remus100",
            horizon=880.0,
            dt=0.05,
            current=(0.0, 0.3),
            options=(("diverge_e", None), ("waves", None), ("wave_seed", 0)),
        ),
    )
}
#: the arm demo (``vcjax demo``): the generic engine, no gains or current
ARM = Experiment(
    "arm",
    "two-link arm drawing a circle (generic engine)",
    "vcjax.experiments.arm",
    horizon=6.0,
    dt=2e-3,
    gains=False,
)


def names() -> tuple[str, ...]:
    """The experiments of ``vcjax simulate``."""
    return tuple(sorted(EXPERIMENTS))


def get(name: str) -> Experiment:
    """The experiment ``name`` (``ValueError`` listing the known ones)."""
    if name not in EXPERIMENTS:
        raise ValueError(f"experiment: expected one of {list(names())}, got {name!r}")
    return EXPERIMENTS[name]
