"""The two-link arm of [`vcjax.vehicles.arm`][vcjax.vehicles.arm] as an engine loop
([`ArmLoop`][vcjax.loops.arm.ArmLoop]): its end
effector held on a path by the generic engine, with joint-torque limits.

Coordinates: the arm moves in a vertical plane, ``x`` horizontal, ``y`` up (gravity ``-y``); the
path's first two coordinates (north, east) are read as ``(x, y)`` of that plane. The default path
is the circle of ``vcjax demo`` (centre ``(1.0, 0.6)`` m, radius 0.35 m), travelled at 0.3 m/s.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, NamedTuple

import jax.numpy as jnp

from vcjax import paths
from vcjax._checks import check_positive
from vcjax.loops.engine import EngineGains, EngineLoop, engine_gains
from vcjax.vehicles.arm import TWO_LINK_ARM, ArmParams, arm_end_effector, arm_params

__all__ = ["ArmLoopParams", "arm_loop_params", "ArmLoop"]


class ArmLoopParams(NamedTuple):
    """The arm's [`ArmParams`][vcjax.vehicles.arm.ArmParams] fields and its joint-torque limits.

    Attributes:
        l1: link 1's length [m] (the fields l1 ... g as in ``ArmParams``).
        l2: link 2's length [m].
        lc1: joint-to-centre-of-mass distance of link 1 [m].
        lc2: the same of link 2 [m].
        m1: link 1's mass [kg].
        m2: link 2's mass [kg].
        I1: link 1's inertia about its centre of mass [kg m^2].
        I2: link 2's inertia about its centre of mass [kg m^2].
        g: gravity [m/s^2].
        tau_max: (2,) joint-torque limits [N m].
    """

    l1: Any
    l2: Any
    lc1: Any
    lc2: Any
    m1: Any
    m2: Any
    I1: Any
    I2: Any
    g: Any
    tau_max: Any


def arm_loop_params(tau_max=(40.0, 15.0), dtype=None, **arm) -> ArmLoopParams:
    """Validated [`ArmLoopParams`][vcjax.loops.arm.ArmLoopParams] (``arm``:
    [`arm_params`][vcjax.vehicles.arm.arm_params]
    keywords)."""
    check_positive("tau_max", tau_max, (2,))
    a = arm_params(**arm)
    dtype = jnp.asarray(0.0).dtype if dtype is None else dtype
    vals = [jnp.asarray(v, dtype) for v in a] + [jnp.asarray(tau_max, dtype)]
    return ArmLoopParams(*vals)


def _arm(p: ArmLoopParams) -> ArmParams:
    return ArmParams(*p[:9])


@dataclasses.dataclass(frozen=True)
class ArmLoop(EngineLoop):
    """Two-link arm, end effector on a path, engine-computed torques (``"vcm"``)."""

    vehicle: ClassVar[str] = "arm"
    initial_keys: ClassVar[dict[str, float]] = {
        "q1_deg": 20.0,
        "q2_deg": 75.0,
        "qd1": 0.2,
        "qd2": -0.1,
    }
    noise_channels: ClassVar[dict[str, int]] = {"angle_std_deg": 2, "rate_std_deg": 2}
    default_speed: ClassVar[float] = 0.3
    #: an arm in air: no water current
    feels: ClassVar[dict[str, bool | str]] = {
        "force": True,
        "current": "an arm in air feels no water",
        "varying_current": "an arm in air feels no water",
        "waves": "an arm in air feels no sea",
    }

    @classmethod
    def default_path(cls):
        """The demo's circle: centre (1.0, 0.6) m, radius 0.35 m."""
        return paths.circle(center=(1.0, 0.6), radius=0.35, clockwise=False)

    def default_params(self, dtype=None) -> ArmLoopParams:
        return arm_loop_params(dtype=dtype)

    def param_names(self):
        return ArmLoopParams._fields

    def default_model_fields(self):
        return ("m1", "m2", "I1", "I2", "lc1", "lc2")

    def default_gains(self) -> EngineGains:
        return engine_gains(P_G=(4.0, 4.0), P_Phi=(6.0, 6.0), sigma=2.0)

    def mass_matrix(self, q, p):
        return TWO_LINK_ARM.mass_matrix(q, _arm(p))

    def bias_force(self, q, qd, p):
        return TWO_LINK_ARM.bias_force(q, qd, _arm(p))

    def point(self, q, p):
        return arm_end_effector(q, _arm(p))

    def initial_from(self, v: dict):
        q0 = jnp.stack([v["q1_deg"], v["q2_deg"]])
        return q0, jnp.stack([v["qd1"], v["qd2"]])

    def measure(self, x, noise):
        q, qd = x
        return q + noise[:2], qd + noise[2:]
