"""The closed-loop abstraction, plant side: [`Loop`][vcjax.loops.loop.Loop].

A [`Loop`][vcjax.loops.loop.Loop] is *static* (a frozen, hashable dataclass: vehicle, controller,
path kind and the
static options of the law), so jitted rollouts compile once per loop; everything continuous is
traced: the [`Scenario`][vcjax.loops.types.Scenario] (initial state, path coefficients, current,
desired speed, plant and design parameters) and the loop's gains (a NamedTuple pytree).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from vcjax import paths
from vcjax.loops.law import Law, required
from vcjax.loops.params import gains_from_json, gains_to_json, param_names
from vcjax.loops.types import GainSpec, Scenario, Signals
from vcjax.rollout import Trajectory

__all__ = ["Loop", "REQUIRED"]


@dataclasses.dataclass(frozen=True)
class Loop:
    """A closed loop: vehicle (plant, design model, actuator map) x controller x path kind.

    Static and hashable (a new gain, current or start never recompiles). Subclasses define the
    class attributes and the methods marked *required*; see [`vcjax.loops`][vcjax.loops] for a
    walk-through.

    Attributes:
        controller: the law's name (one of [`controllers`][vcjax.loops.registry.controllers]).
        path: the static path kind ([`vcjax.paths.Path`][vcjax.paths.Path]); coefficients live in
            ``Scenario.path``.
        smooth: smooth (``tanh``) actuator saturation in the plant, so gradients pass.
    """

    controller: str
    path: paths.Path
    smooth: bool = False

    #: registry name of the vehicle ("infante", "odin", "arm", ...)
    vehicle: ClassVar[str] = ""
    #: the laws: controller name -> [`Law`][vcjax.loops.law.Law] (the controller side)
    laws: ClassVar[Mapping[str, Law]] = {}
    #: the controllers this vehicle's loop supports (default: the names of ``laws``)
    controllers: ClassVar[tuple[str, ...]] = ()
    #: the controller a config means when it names none
    default_controller: ClassVar[str] = ""
    #: [initial] keys of sweeps/tuning: name -> default value (sampled ranges set by configs)
    initial_keys: ClassVar[dict[str, float]] = {}
    #: sensor-noise channels: name -> number of entries (see ``measure``)
    noise_channels: ClassVar[dict[str, int]] = {}
    #: desired speed of the nominal scenario [m/s]
    default_speed: ClassVar[float] = 1.0
    #: what the plant feels of the environment, by kind
    #: ([`vcjax.environment.KINDS`][vcjax.environment.KINDS]):
    #: ``True``, or the one-line reason it cannot; a kind not named is refused with a generic
    #: reason ([`vcjax.loops.check_environment`][vcjax.loops.scenario.check_environment]).
    #: ``"current"``: ``plant_args`` uses
    #: its current; ``"varying_current"``: ``with_current``; ``"waves"`` (water that varies
    #: in space): ``plant_in_sea``; ``"force"``:
    #: [`Scenario.disturbance`][vcjax.loops.loop.Scenario.disturbance]. Sensor noise
    #: (``"noise"``) is felt by a loop with ``noise_channels`` (and ``measure``).
    feels: ClassVar[Mapping[str, bool | str]] = {}
    #: the keys of ``signals(...).act`` (the actuator signals whose maxima the metrics report as
    #: ``max_abs_<key>``), declared by a loop that defines ``signals`` so that a sweep need not
    #: trace the controller to learn them; None: learnt by tracing (a subclass that overrides
    #: ``signals`` without declaring them again is traced too)
    act_signals: ClassVar[tuple[str, ...] | None] = None

    @classmethod
    def can_feel(cls, kind: str) -> bool:
        """Whether the plant (or, for ``"noise"``, the controller) feels ``kind``."""
        if kind == "noise":
            return bool(cls.noise_channels) or cls.feels.get(kind) is True
        return cls.feels.get(kind) is True

    @classmethod
    def refusal(cls, kind: str) -> str:
        """Why the loop cannot feel ``kind`` (its declared reason, or a generic one)."""
        why = cls.feels.get(kind)
        if isinstance(why, str):
            return why
        if kind == "waves":
            return "its plant has no door for the water's orbital motion"
        if kind == "noise":
            return "it models no sensors (no noise_channels)"
        return "its plant has no door for it"

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "laws" in cls.__dict__ and "controllers" not in cls.__dict__:
            cls.controllers = tuple(cls.laws)

    @property
    def law(self) -> Law | None:
        """The [`Law`][vcjax.loops.law.Law] of ``controller`` (None for a loop that
        implements its controller in its own methods)."""
        return type(self).laws.get(self.controller)

    def __post_init__(self):
        if self.controller not in self.controllers:
            raise ValueError(
                f"controller: vehicle {self.vehicle!r} supports {list(self.controllers)}, "
                f"got {self.controller!r}"
            )
        if not isinstance(self.path, paths.Path):
            raise ValueError(f"path: expected a vcjax.paths.Path, got {type(self.path).__name__}")

    # ---------------------------------------------------------------- required
    @classmethod
    @required
    def default_path(cls):
        """``(Path, coeffs)``: the vehicle's default path."""
        raise NotImplementedError

    @required
    def position(self, eta, params):
        """(3,) NED point that must follow the path (the craft; an end effector) [m]."""
        raise NotImplementedError

    @required
    def default_params(self, dtype=None):
        """The vehicle's nominal parameters (a NamedTuple of arrays)."""
        raise NotImplementedError

    def validate_params(self, params, name: str = "plant"):
        """Eagerly check vehicle parameters however they were built (e.g. ``_replace``d);
        raise ``ValueError`` naming ``name.field``. Default: the parameters must be of the type
        ``default_params`` returns; a vehicle overrides it with its module's ``validate``."""
        kind = type(self.default_params())
        if not isinstance(params, kind):
            raise ValueError(f"{name}: expected {kind.__name__}, got {type(params).__name__}")
        return params

    def default_gains(self):
        """The controller's default gains (a NamedTuple pytree): the law's."""
        return self._require_law("default_gains").default_gains(self)

    def gain_specs(self) -> tuple[GainSpec, ...]:
        """The tunable gain groups of ``controller``: the law's."""
        return self._require_law("gain_specs").gain_specs(self)

    def _require_law(self, what):
        if self.law is None:
            raise NotImplementedError(f"{type(self).__name__}.{what}: no law and no override")
        return self.law

    @required
    def plant(self, t, x, u, args):
        """Vector field ``x_dot = f(t, x, u, args)`` (args from ``plant_args``)."""
        raise NotImplementedError

    @required
    def control(self, t, x, z, ctrl):
        """Controller ``(u, z_dot, aux)`` (ctrl from ``ctrl_params``)."""
        raise NotImplementedError

    @required
    def plant_args(self, sc: Scenario, current, current_dot):
        """The plant's traced arguments for plant parameters ``sc.plant`` and a current (3,)
        NED [m/s] with its rate (3,) [m/s^2], which go into the plant's one water door
        ([`WaterMotion`][vcjax.environment.component.WaterMotion], every plant's ``water``)."""
        raise NotImplementedError

    @required
    def ctrl_params(self, gains, sc: Scenario):
        """The controller's traced parameters (design model from ``sc.design``; a loop with laws
        calls ``law.params(self, gains, sc, self.law_design(sc))``)."""
        raise NotImplementedError

    def law_design(self, sc: Scenario):
        """What the loop derives from the design vehicle ``sc.design`` for its laws, the last
        argument of [`Law.params`][vcjax.loops.law.Law.params] (traced; the vehicle's
        convention, written in its loop's docstring). Default: ``sc.design`` itself."""
        return sc.design

    @required
    def initial_state(self, sc: Scenario):
        """``(x0, z0)``: plant and controller states at ``t = 0``."""
        raise NotImplementedError

    @required
    def signals(self, traj: Trajectory, sc: Scenario) -> Signals:
        """Per-step signals of a run for metrics and losses (true values)."""
        raise NotImplementedError

    @required
    def initial_from(self, values: dict):
        """``(eta0, nu0)`` from the ``initial_keys`` values (traced scalars, SI units:
        keys ending in ``_deg`` are given here already in radians)."""
        raise NotImplementedError

    # ---------------------------------------------------------------- optional
    def param_names(self) -> tuple[str, ...]:
        """Plant/design parameter names accepted by ``[model_error]`` and parameter files."""
        return param_names(self.default_params())

    def default_model_fields(self) -> tuple[str, ...]:
        """Parameters a ``[model_error]`` perturbs when it names none."""
        return self.param_names()

    def symmetric_pairs(self) -> tuple[tuple[str, int, str, int], ...]:
        """Gain entries ``(group_a, i, group_b, j)`` the loop depends on only through their sum
        and product (Baumgarte pairs ``p_G``, ``p_Phi`` of one holonomic row), so that a tuner
        starting with them equal is at a critical point (see ``tuning.params``)."""
        return () if self.law is None else self.law.symmetric_pairs(self)

    def measure(self, x, noise):
        """The state the controller sees: ``x`` with ``noise`` (concatenated
        ``noise_channels``, SI units) added. Default: no sensors modelled."""
        raise NotImplementedError(f"{type(self).__name__}: no sensor-noise model")

    def noise_std(self, stds: dict) -> np.ndarray:
        """Concatenated standard deviations from a ``{channel: std}`` dict (SI units)."""
        parts = [np.full(n, float(stds.get(k, 0.0))) for k, n in self.noise_channels.items()]
        return np.concatenate(parts) if parts else np.zeros(0)

    def with_current(self, args, current, current_dot):
        """``args`` with a new current (3,) and rate (3,) (time-varying currents)."""
        raise NotImplementedError(f"{type(self).__name__}: no time-varying current")

    def plant_in_sea(self, t, x, u, args, water):
        """The plant's vector field in a sea (loops that feel ``"waves"``).

        Args:
            t, x, u: as ``plant``; args: the plant's arguments with the current already in
                them (``plant_args``, ``with_current``);
            water: [`Water`][vcjax.loops.types.Water] (the sea and the current at this time).

        The loop knows how its plant takes the water: it evaluates ``water`` at the vehicle's
        NED position (every integrator stage: the sea depends on where the vehicle is), hands
        the velocity and material acceleration to the plant's water door
        (``water.at(t, p)``, a [`WaterMotion`][vcjax.environment.component.WaterMotion]) and
        adds the
        Froude–Krylov correction
        ([`current_door_correction`][vcjax.environment.waves.current_door_correction]). A calm
        sea (``hs = 0``) must give exactly ``plant``'s result.
        """
        raise NotImplementedError(f"{type(self).__name__}: no waves ({self.refusal('waves')})")

    def gains_to_json(self, gains) -> dict:
        """The gains-JSON object, with the ``"vehicle"`` and ``"controller"`` they are for."""
        return {"vehicle": self.vehicle, "controller": self.controller, **gains_to_json(gains)}

    def gains_from_json(self, d: dict, base=None):
        """Gains from a JSON object (entries missing keep ``base``, default the defaults): the
        one reader ([`gains_from_json`][vcjax.loops.params.gains_from_json]) with the law's checks.

        A file that records its ``"vehicle"`` (what
        [`gains_to_json`][vcjax.loops.params.gains_to_json] writes) is refused
        for another vehicle, and one whose ``"controller"`` is not a controller of this vehicle
        too (``ValueError`` naming both); a vehicle's controllers share its gains (a sweep runs
        one gains file with every variant). Older files without these keys still load."""
        if isinstance(d, dict) and ("vehicle" in d or "controller" in d):
            d = dict(d)
            vehicle, ctrl = d.pop("vehicle", self.vehicle), d.pop("controller", None)
            if vehicle != self.vehicle or (ctrl is not None and ctrl not in self.controllers):
                raise ValueError(
                    f"gains file: these are gains of vehicle {vehicle!r} (controller {ctrl!r}), "
                    f"not of {self.vehicle!r} (controllers {list(self.controllers)})"
                )
        if self.law is not None:
            return self.law.gains_from_json(self, d, base)
        return gains_from_json(d, self.default_gains() if base is None else base)

    def describe(self) -> str:
        return f"{self.vehicle} / {self.controller} on a {self.path.name}"


#: the methods a [`Loop`][vcjax.loops.loop.Loop] subclass must define
#: (``default_gains``/``gain_specs`` too when
#: it has no [`Loop.laws`][vcjax.loops.loop.Loop.laws])
REQUIRED = tuple(
    n for n in dir(Loop) if getattr(getattr(Loop, n, None), "__vcjax_required__", False)
)
