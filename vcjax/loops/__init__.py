"""Closed loops by name: the layer under ``vcjax simulate``, ``vcjax sweep`` and ``vcjax tune``.

A *loop* assembles a vehicle's plant, the controller's design model, a law and the actuator map
(and the thruster allocation where there is one) into the ``(plant, controller)`` pair that
[`vcjax.rollout.rollout`][vcjax.rollout.rollout] runs. Three kinds of data, kept apart:

* the [`Loop`][vcjax.loops.loop.Loop] itself — static and hashable (vehicle, controller, path
  kind, static law options such as ``smooth``): one compilation per loop;
* the [`Scenario`][vcjax.loops.types.Scenario] — traced, the same container for every loop: initial
  state ``eta0``/``nu0``, ``current`` (the water's NED velocity (3,) [m/s], built from a speed
  and a direction with [`current_ned`][vcjax.environment.current.current_ned]), ``u_d``, ``varpi0``,
  the
  path's coefficients, the ``plant`` and ``design`` parameters, a constant ``disturbance`` force,
  and optionally a ``sea`` (a [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea]) with its
  ``origin_depth``;
* the gains — a NamedTuple pytree, traced (a new gain value never recompiles).

[`simulate`][vcjax.loops.disturbances.simulate] rolls any loop out, optionally with disturbances
that wrap
any loop ([`Disturbances`][vcjax.loops.disturbances.Disturbances]: a Gauss–Markov current, sensor
noise) and a
sea when the scenario has one (loops that feel ``"waves"``,
[`Loop.plant_in_sea`][vcjax.loops.loop.Loop.plant_in_sea]), and
the components of the scenario's ``environment`` ([`vcjax.environment`][vcjax.environment]: any
current,
sea, noise or force, one seam);
model error is just a ``plant`` that differs from ``design``.
[`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] turns any loop's
[`Signals`][vcjax.loops.types.Signals] into the
one set of metrics and health flags.

Registry (``vehicle -> Loop subclass``)::

    loops.vehicles()                     # ("arm", "infante", "odin", ...)
    loops.controllers("infante")         # ("vcm", "vcm_integral", "vcm_ilos", "ilos", "los_pid")
    loop = loops.make_loop("infante", "vcm_integral", path=paths.CIRCLE)   # path: a Path kind
    path, coeffs = loops.default_path("infante")                           # the vehicle's default
    sc = loops.make_scenario(loop, coeffs, current=(0.0, 0.5, 0.0))        # validated, eager
    traj = loops.simulate(loop, loop.default_gains(), sc, RolloutConfig(num_steps=400), 0.05)

How to add a law to a vehicle (one new file + one
[`register_law`][vcjax.loops.registry.register_law] line;
``tests/test_new_law.py`` defines a heading law for ``infante`` entirely inside the test file,
then simulates, sweeps and tunes it): subclass [`Law`][vcjax.loops.law.Law] as a frozen dataclass
(its fields are the law's static options) with ``default_gains``, ``gain_specs`` (build them with
[`gain_spec`][vcjax.loops.params.gain_spec]), ``params``, ``initial_state`` and ``step``; what
``params`` and ``step``
receive is the vehicle's convention, written in its loop module's docstring (e.g.
[`vcjax.loops.infante`][vcjax.loops.infante]). Then ``loops.register_law("infante", "my_law",
MyLaw())``
(which traces one step of the loop with the law, [`check_step`][vcjax.loops.registry.check_step],
and refuses it naming what
is wrong: a ``step`` without ``z``, gains that are not a NamedTuple, a force of another shape
than the vehicle's other laws give).

How to add a vehicle (one new file + one [`register`][vcjax.loops.registry.register] line;
``tests/test_loops.py``
defines a loop entirely inside the test file and sweeps and tunes it):

1. Subclass [`Loop`][vcjax.loops.loop.Loop] (or [`EngineLoop`][vcjax.loops.engine.EngineLoop] for
any
   mechanical system held on a path by the generic engine) as a frozen dataclass; extra static
   options are dataclass fields. Class attributes: ``vehicle`` (the registry name), ``laws``
   (controller name -> [`Law`][vcjax.loops.law.Law]; ``controllers`` follows), ``initial_keys``
   (the ``[initial]`` keys of sweep/tune configs with their defaults; keys ending in ``_deg``
   are given in degrees in configs and arrive in radians), ``noise_channels`` (sensor-noise
   channel name -> entries; leave empty if you model no sensors), ``feels`` (what the plant
   feels of the environment: ``{"current": True, "varying_current": True, "waves": "why
   not", "force": True}``; a kind it does not feel is refused by name before any work,
   [`check_environment`][vcjax.loops.scenario.check_environment]), ``default_speed``.
2. Implement (``register`` refuses a class missing one, naming them):
   ``default_params(dtype)`` — the plant parameters (a NamedTuple; its field names, dotted for
   nested NamedTuples, are the names ``[model_error] fields`` and parameter files use;
   restrict them with ``param_names()``, choose the default perturbed set with
   ``default_model_fields()``); ``default_path()`` (classmethod) — ``(Path, coeffs)``;
   ``plant(t, x, u, args)``, ``control(t, x, z, ctrl) -> (u, z_dot, aux)`` (usually: the
   law's ``step`` then the actuator map); ``plant_args(sc, current, current_dot)`` (the
   plant's arguments, the water in one door:
   [`WaterMotion`][vcjax.environment.component.WaterMotion]),
   ``ctrl_params(gains, sc)`` (``law.params(self, gains, sc, self.law_design(sc))``;
   ``law_design(sc)``, default ``sc.design``, is what the laws are designed on),
   ``initial_state(sc) -> (x0, z0)``, ``initial_from(values) -> (eta0, nu0)``,
   ``position(eta, params) -> (3,)`` (where the path must be: craft position, end effector);
   ``signals(traj, sc) -> Signals`` (true errors, commands over limits, actuator
   magnitudes); optionally ``measure(x, noise)``, ``with_current(args, current, rate)`` and
   ``plant_in_sea(t, x, u, args, water)`` ([`Water`][vcjax.loops.types.Water]).
   Gains (``default_gains``, ``gain_specs``, ``symmetric_pairs``, ``gains_from_json``) come
   from the law; a loop without ``laws`` defines ``default_gains`` and ``gain_specs`` itself.
3. ``loops.register(MyLoop)`` (a name already taken is refused unless ``replace=True``). Then
   ``[scenario] vehicle = "my_vehicle"`` works in sweep and tune configs, and [`tuning`][tuning]
   tunes ``gain_specs()``.

Modules: [`types`][vcjax.loops.types] (Scenario, Signals, GainSpec), [`loop`][vcjax.loops.loop]
(Loop: the plant side), [`law`][vcjax.loops.law] (Law: the controller side),
[`params`][vcjax.loops.params] (parameter names, the gains-JSON reader,
[`gain_spec`][vcjax.loops.params.gain_spec]),
[`disturbances`][vcjax.loops.disturbances] (Disturbances,
[`simulate`][vcjax.loops.disturbances.simulate]), [`registry`][vcjax.loops.registry],
[`scenario`][vcjax.loops.scenario] ([`make_scenario`][vcjax.loops.scenario.make_scenario], parameter
files),
[`geometry`][vcjax.loops.geometry] (path helpers), one module per vehicle.

Parameter overrides (``[scenario] params`` / ``plant_params`` files of sweep and tune configs,
e.g. a ``vcjax fit`` result): [`replace_params`][vcjax.loops.params.replace_params] with names from
``loop.param_names()``; [`read_param_file`][vcjax.loops.scenario.read_param_file] reads a flat
``{name: value}`` map or a ``fit``
output's ``"estimates"`` map and rejects unknown names, listing the valid ones.
"""

from __future__ import annotations

from vcjax.loops.arm import ArmLoop, ArmLoopParams, arm_loop_params
from vcjax.loops.disturbances import (
    DisturbanceParams,
    Disturbances,
    gauss_markov_params,
    simulate,
)
from vcjax.loops.engine import EngineAux, EngineGains, EngineLaw, EngineLoop, engine_gains
from vcjax.loops.geometry import (
    path_errors,
    path_frames,
    path_polyline,
    path_poses,
    start_parameter,
)
from vcjax.loops.infante import InfanteGains, InfanteLoop, infante_gains
from vcjax.loops.law import Law
from vcjax.loops.loop import Loop
from vcjax.loops.odin import OdinGains, OdinLoop, default_odin_gains, odin_gains
from vcjax.loops.params import (
    gain_spec,
    gains_from_json,
    gains_to_json,
    get_param,
    param_names,
    replace_params,
)
from vcjax.loops.pm import rh_bound
from vcjax.loops.registry import (
    check_step,
    controllers,
    default_path,
    loop_class,
    make_loop,
    register,
    register_law,
    vehicles,
)
from vcjax.loops.remus100 import Remus100Loop
from vcjax.loops.scenario import (
    apply_params,
    check_disturbances,
    check_environment,
    make_scenario,
    read_param_file,
)
from vcjax.loops.types import GainSpec, Scenario, Signals, Water

__all__ = [
    "Disturbances",
    "DisturbanceParams",
    "GainSpec",
    "Law",
    "Loop",
    "Scenario",
    "Signals",
    "Water",
    "InfanteGains",
    "InfanteLoop",
    "infante_gains",
    "ArmLoop",
    "ArmLoopParams",
    "arm_loop_params",
    "EngineAux",
    "EngineGains",
    "EngineLaw",
    "EngineLoop",
    "engine_gains",
    "OdinGains",
    "OdinLoop",
    "odin_gains",
    "default_odin_gains",
    "Remus100Loop",
    "gain_spec",
    "gains_from_json",
    "gains_to_json",
    "gauss_markov_params",
    "get_param",
    "param_names",
    "replace_params",
    "rh_bound",
    "simulate",
    "start_parameter",
    "path_polyline",
    "path_frames",
    "path_poses",
    "path_errors",
    "register",
    "register_law",
    "check_step",
    "vehicles",
    "loop_class",
    "controllers",
    "make_loop",
    "default_path",
    "make_scenario",
    "check_disturbances",
    "check_environment",
    "read_param_file",
    "apply_params",
]

register(InfanteLoop, check=False)
register(OdinLoop, check=False)
register(ArmLoop, check=False)
register(Remus100Loop, check=False)
