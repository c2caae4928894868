"""What system identification needs to know about a vehicle: its logged channels and one step.

A [`FitModel`][vcjax.identify.models.FitModel] maps a vehicle's plant onto flat vectors, the form
the multiple-shooting
solver works with: the state ``x`` (n_x,) in the order of the log's state columns, the command
``u`` (n_u,) in the order of its command columns, and one discrete step

    x_next = step(vehicle_params, v_c, x, u, dt)

either PythonVehicleSimulator's own Euler step (``"pvs"``, REMUS 100 only) or an integrator of
[`vcjax.integrators`][vcjax.integrators] applied to the continuous plant with the command held over
the step.
``v_c`` (2,) is the current as the water's NED velocity ``[north, east]`` [m/s], from a speed and
the direction it flows towards with [`current_vector`][vcjax.identify.models.current_vector].

Registered: ``remus100`` ([`vcjax.vehicles.remus100`][vcjax.vehicles.remus100], 6-DOF, 15 states)
and ``infante``
([`vcjax.vehicles.infante`][vcjax.vehicles.infante], horizontal plane, 8 states).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from vcjax.environment import WaterMotion
from vcjax.integrators import INTEGRATORS, get_integrator
from vcjax.vehicles import infante as inf
from vcjax.vehicles import remus100 as rm

__all__ = ["FitModel", "FIT_MODELS", "get_fit_model", "current_vector", "scalar_fields"]


@dataclasses.dataclass(frozen=True)
class FitModel:
    """A vehicle as the identification sees it (static).

    Attributes:
        vehicle: registry name.
        state_columns: names of the log columns forming the flat state, in order.
        command_columns: names of the command columns, in order.
        angle_columns: state columns that are angles [rad] (residuals wrapped to (-pi, pi]).
        units: unit of every state column (figures, reports).
        steps: the step names this vehicle supports.
        nominal: ``nominal(dtype) -> params`` (the vehicle's parameter NamedTuple).
        make_args: ``make_args(params, v_c (2,)) -> plant args``.
        unpack: flat state (n_x,) -> the plant's state NamedTuple; pack: the inverse.
        plant: the continuous vector field ``f(t, state, u, args) -> state_dot``.
        pvs_step: PVS's discrete step ``(state, u, args, dt) -> state`` or ``None``.
        actuator_limits: ``actuator_limits(params) -> {state column: limit}``: the magnitude
            an actuator state cannot exceed (the plant saturates it there), in the column's unit.
        actuator_coeffs: parameters that multiply an actuator's angle (their estimate scales
            by pi/180 when the actuator is logged in degrees).
    """

    vehicle: str
    state_columns: tuple[str, ...]
    command_columns: tuple[str, ...]
    angle_columns: tuple[str, ...]
    units: tuple[str, ...]
    steps: tuple[str, ...]
    nominal: Callable
    make_args: Callable
    unpack: Callable
    pack: Callable
    plant: Callable
    pvs_step: Callable | None = None
    actuator_limits: Callable | None = None
    actuator_coeffs: tuple[str, ...] = ()

    @property
    def n_x(self) -> int:
        return len(self.state_columns)

    @property
    def n_u(self) -> int:
        return len(self.command_columns)

    def angle_mask(self) -> np.ndarray:
        """(n_x,) bool, True for the angle channels."""
        return np.array([c in self.angle_columns for c in self.state_columns])

    def make_step(self, step: str) -> Callable:
        """``step(params, v_c, x, u, dt) -> x_next`` on flat vectors (pure, jittable).

        Raises:
            ValueError: naming ``step`` when this vehicle does not support it.
        """
        if step not in self.steps:
            raise ValueError(
                f"step: {step!r} is not available for vehicle {self.vehicle!r}; "
                f"choose one of {list(self.steps)}"
            )
        if step == "pvs":
            pvs = self.pvs_step

            def step_fn(params, v_c, x, u, dt):
                args = self.make_args(params, v_c)
                return self.pack(pvs(self.unpack(x), u, args, dt))

            return step_fn

        integrate = get_integrator(step)
        plant = self.plant

        def field(t, x, args_u):
            args, u = args_u
            return plant(t, x, u, args), None

        def step_fn(params, v_c, x, u, dt):
            args = self.make_args(params, v_c)
            x_next, _ = integrate(field, 0.0 * dt, self.unpack(x), dt, (args, u))
            return self.pack(x_next)

        return step_fn


def current_vector(speed, direction_rad):
    """(2,) NED current ``[V cos beta, V sin beta]`` [m/s] from its speed and the direction it
    flows towards (from north towards east) [rad]."""
    return jnp.stack([speed * jnp.cos(direction_rad), speed * jnp.sin(direction_rad)])


def scalar_fields(params) -> tuple[str, ...]:
    """Names of the 0-d (scalar) fields of a vehicle's parameter NamedTuple."""
    return tuple(
        name
        for name, value in zip(params._fields, params, strict=True)
        if not isinstance(value, tuple) and np.ndim(value) == 0
    )


def _remus_pack(s: rm.Remus100State):
    return jnp.concatenate([s.eta, s.nu, s.act])


def _remus_unpack(x):
    return rm.Remus100State(eta=x[:6], nu=x[6:12], act=x[12:15])


def _infante_pack(s: inf.InfanteState):
    return jnp.concatenate([s.eta, s.nu, s.act])


def _water(v_c):
    """The plant's water door for the horizontal current ``v_c`` (2,): constant, no vertical."""
    v = jnp.concatenate([v_c, jnp.zeros_like(v_c[:1])])
    return WaterMotion(v, jnp.zeros_like(v))


def _infante_unpack(x):
    return inf.InfanteState(eta=x[:3], nu=x[3:6], act=x[6:8])


_INTEGRATOR_STEPS = tuple(sorted(INTEGRATORS))

FIT_MODELS: dict[str, FitModel] = {
    "remus100": FitModel(
        vehicle="remus100",
        state_columns=(
            "x",
            "y",
            "z",
            "phi",
            "theta",
            "psi",
            "u",
            "v",
            "w",
            "p",
            "q",
            "r",
            "delta_r",
            "delta_s",
            "n_rpm",
        ),  # fmt: skip
        command_columns=("delta_r_cmd", "delta_s_cmd", "n_cmd_rpm"),
        angle_columns=("phi", "theta", "psi"),
        units=(
            "m",
            "m",
            "m",
            "rad",
            "rad",
            "rad",
            "m/s",
            "m/s",
            "m/s",
            "rad/s",
            "rad/s",
            "rad/s",
            "rad",
            "rad",
            "rpm",
        ),  # fmt: skip
        steps=("pvs",) + _INTEGRATOR_STEPS,
        nominal=lambda dtype: rm.remus100_params(dtype=dtype),
        make_args=lambda p, v_c: rm.Remus100Args(p, _water(v_c), M_factor=rm.mass_factor(p)),
        unpack=_remus_unpack,
        pack=_remus_pack,
        plant=rm.remus100_plant,
        pvs_step=rm.pvs_step,
        actuator_limits=lambda p: {"delta_r": p.act_max[0], "delta_s": p.act_max[1]},
        actuator_coeffs=("CL_delta_r", "CL_delta_s"),
    ),
    "infante": FitModel(
        vehicle="infante",
        state_columns=("x", "y", "psi", "u", "v", "r", "thrust", "delta"),
        command_columns=("thrust_cmd", "delta_cmd"),
        angle_columns=("psi",),
        units=("m", "m", "rad", "m/s", "m/s", "rad/s", "N", "rad"),
        steps=_INTEGRATOR_STEPS,
        nominal=lambda dtype: inf.infante_params(dtype=dtype),
        make_args=lambda p, v_c: inf.PlantArgs(vehicle=p, water=_water(v_c)),
        unpack=_infante_unpack,
        pack=_infante_pack,
        plant=inf.infante_plant,
        actuator_limits=lambda p: {"delta": p.rudder_max},
        actuator_coeffs=("Y_uudr", "N_uudr"),
    ),
}


def get_fit_model(vehicle: str) -> FitModel:
    """The [`FitModel`][vcjax.identify.models.FitModel] registered as ``vehicle``.

    Raises:
        ValueError: naming ``vehicle`` and listing the registered ones.
    """
    try:
        return FIT_MODELS[vehicle]
    except KeyError:
        raise ValueError(
            f"vehicle: {vehicle!r} has no identification model; choose one of {sorted(FIT_MODELS)}"
        ) from None
