"""vcjax: virtually constrained motion control of underwater vehicles, in JAX.

The public API, by stage of the data flow (each module's docstring has the details):

* [`vcjax.mechanics`][vcjax.mechanics] — the generic VCM engine: ``MechanicalSystem``,
``VirtualConstraints``,
  ``vcm_gains``, ``reaction_force`` (16)/(17) with autodiff constraint Jacobians.
* [`vcjax.vehicles`][vcjax.vehicles] — ``design3dof`` (20), ``sixdof`` (2), ``infante``
(INFANTE-class),
  ``odin`` (ODIN-class), ``remus100`` (PythonVehicleSimulator's REMUS 100).
* [`vcjax.paths`][vcjax.paths], [`vcjax.guidance`][vcjax.guidance] — paths and their frames, path
particle, errors.
* [`vcjax.control`][vcjax.control] — ``vcm`` (path maneuvering (31)/(38)/(41)), ``baselines``
(LOS-PID, ILOS).
* [`vcjax.allocation`][vcjax.allocation] — thruster allocation with limits.
* [`vcjax.integrators`][vcjax.integrators], [`vcjax.rollout`][vcjax.rollout] —
``euler``/``heun``/``rk4``; the scan rollout.
* [`vcjax.loops`][vcjax.loops] — closed loops by name (vehicle x controller x path), one
``Scenario``
  type, disturbances wrapping any loop; [`vcjax.metrics`][vcjax.metrics] — one metrics function for
  all.
* [`vcjax.environment`][vcjax.environment] — what the world does to a vehicle, one seam: currents
(constant,
  Gauss–Markov), waves, sensor noise, forces; a new disturbance is one component + ``register``.
* [`vcjax.sweep`][vcjax.sweep] — Monte-Carlo batches of any loop.
* [`vcjax.config`][vcjax.config] — one configuration system (sections, types, units, older
spellings).
* [`vcjax.experiments`][vcjax.experiments] — the presets of ``vcjax simulate`` as data
(``Experiment``: the
  paper's two experiments, the REMUS 100 mission, the arm demo), on top of the loops;
  [`vcjax.plots`][vcjax.plots] — figures.
* [`vcjax.identify`][vcjax.identify] — ``vcjax fit``: plant parameters from logged runs by multiple
shooting.
* [`vcjax.search`][vcjax.search] — ``vcjax falsify``: the worst current, sea and start within an
envelope
  (``vcjax.falsify(loop, gains, envelope, metric, ...)``, imported on first use).

The library never enables float64 and never jits your functions for you. The programs it compiles
itself use XLA's faster-compiling CPU kernel generator, as the ``vcjax`` command line does;
``vcjax.jit`` in place of ``jax.jit`` gives your own functions the same, and
``vcjax.fast_compile()``, called before the first JAX computation, gives it to every program of
the process ([`vcjax.runtime.compiler`][vcjax.runtime.compiler]).
"""

from vcjax.integrators import euler, get_integrator, heun, rk4
from vcjax.mechanics import (
    Diagnostics,
    MechanicalSystem,
    Underactuation,
    VCMGains,
    VirtualConstraints,
    constraint_terms,
    reaction_force,
    underactuated_reaction_force,
    vcm_gains,
)
from vcjax.paths import Path, PathFrame, path_frame
from vcjax.rollout import RolloutConfig, Trajectory
from vcjax.runtime.compiler import fast_compile, jit

__all__ = [
    "Diagnostics",
    "MechanicalSystem",
    "Path",
    "PathFrame",
    "RolloutConfig",
    "Trajectory",
    "Underactuation",
    "VCMGains",
    "VirtualConstraints",
    "constraint_terms",
    "euler",
    "fast_compile",
    "get_integrator",
    "heun",
    "jit",
    "path_frame",
    "reaction_force",
    "rk4",
    "underactuated_reaction_force",
    "vcm_gains",
]

__version__ = "0.1.0"


def __getattr__(name):
    """``vcjax.falsify``: [`vcjax.search.falsify`][vcjax.search.core.falsify], imported on first use
    (it pulls in the
    loops and the sweep machinery, which ``import vcjax`` does not)."""
    if name == "falsify":
        from vcjax.search import falsify

        return falsify
    raise AttributeError(f"module 'vcjax' has no attribute {name!r}")
