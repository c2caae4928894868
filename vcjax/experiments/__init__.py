"""The experiments ``vcjax simulate NAME`` runs (``vcjax demo`` is ``vcjax simulate arm``).

An experiment is data ([`Experiment`][vcjax.experiments.base.Experiment],
[`vcjax.experiments.base`][vcjax.experiments.base]): the loop and the
scenario of each of its runs, its default horizon, step and current, its typed options (a frozen
[`Options`][vcjax.experiments.base.Options] dataclass; ``vcjax simulate NAME`` generates its flags
from the fields, so an
option that does not apply to an experiment cannot be given), its metrics and figures, and its
own extras. Every experiment runs through the same jitted runner and the same
[`Experiment.run`][vcjax.experiments.base.Experiment.run].

Every experiment takes ``--horizon``, ``--dt``, ``--max-steps``, ``--out``, ``--no-x64`` and
``--overwrite``; ``--gains FILE`` (the gains JSON ``vcjax tune`` writes for its loop) where
``Experiment.gains``, ``--current V_N V_E`` where ``Experiment.current`` is set; and its
options' flags.

The experiments (``EXPERIMENTS``): ``sim1`` (Simulation 1 of the paper: INFANTE-class on a
line, every controller; its loop option and ``--timing``, ``--diverge-e``), ``sim2`` (Simulation 2:
ODIN-class on a helix, both actuation modes; ``--actuation``, ``--diverge-e``, ``--waves``,
``--wave-seed``), ``remus100`` (a 3-D lawnmower survey of the PVS REMUS 100 under a cross
current, every controller; ``--diverge-e``, ``--waves``, ``--wave-seed``), ``arm`` (the two-link
arm drawing a circle with the generic engine; ``vcjax demo``).

``--waves HS TP DIR_DEG`` puts every run in one random JONSWAP sea
([`sea_state`][vcjax.environment.waves.sea_state], 64 components, long-crested) drawn from
``PRNGKey(--wave-seed)`` (default 0), [`vcjax.experiments.seas`][vcjax.experiments.seas].

Importing this package initialises no JAX backend (the CLI builds its parser from the registry
before it chooses the precision and the devices).
"""

from __future__ import annotations

from vcjax.experiments.arm import ARM
from vcjax.experiments.base import Experiment, Options, Outcome, PathBound, Setup, flags, rollout
from vcjax.experiments.remus100 import REMUS100
from vcjax.experiments.sim1 import SIM1
from vcjax.experiments.sim2 import SIM2

__all__ = [
    "Experiment",
    "Options",
    "PathBound",
    "Setup",
    "Outcome",
    "EXPERIMENTS",
    "flags",
    "get",
    "names",
    "rollout",
]

#: name -> [`Experiment`][vcjax.experiments.base.Experiment], the presets of ``vcjax simulate NAME``
EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in (SIM1, SIM2, REMUS100, ARM)}


def names() -> tuple[str, ...]:
    """The experiments of ``vcjax simulate``."""
    return tuple(sorted(EXPERIMENTS))


def get(name: str) -> Experiment:
    """The experiment ``name`` (``ValueError`` listing the known ones)."""
    if name not in EXPERIMENTS:
        raise ValueError(f"experiment: expected one of {list(names())}, got {name!r}")
    return EXPERIMENTS[name]
