"""The traced parameters every path-following law of [`vcjax.control`][vcjax.control] takes."""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax._checks import check_array, check_positive

__all__ = ["LawParams", "law_params"]


class LawParams(NamedTuple):
    """Everything continuous a path-following law uses (traced).

    Attributes:
        gains: the law's gains ([`PMGains`][vcjax.control.vcm.PMGains] for the VCM law,
            [`BaselineGains`][vcjax.control.baselines.BaselineGains] for LOS-PID / ILOS).
        model: [`Design3DOF`][vcjax.vehicles.design3dof.Design3DOF], the controller's design model.
        u_d: () desired surge speed [m/s].
        k_rudder: () sway force the rudder produces per unit yaw moment [1/m] (Remark 4; 0 if
            the rudder's sway force is neglected).
        int_limit: () anti-windup clamp on the integral states [m s] (each component of
            ``int(eps)`` for the VCM law; LOS-PID's ``e_int`` when ``k_ei = 0``).
        path: the path's coefficients (see [`vcjax.paths`][vcjax.paths]).
    """

    gains: Any
    model: Any
    u_d: Any
    k_rudder: Any
    int_limit: Any
    path: Any


def law_params(gains, model, path, u_d=2.0, k_rudder=0.0, int_limit=50.0) -> LawParams:
    """Validated [`LawParams`][vcjax.control.params.LawParams] (``u_d``, ``int_limit`` > 0; finite
    scalar ``k_rudder``)."""
    check_positive("u_d", u_d, ())
    check_array("k_rudder", k_rudder, ())
    check_positive("int_limit", int_limit, ())
    f = lambda x: jnp.asarray(x, dtype=float)
    return LawParams(gains, model, f(u_d), f(k_rudder), f(int_limit), path)
