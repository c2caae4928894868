"""The data every loop shares: [`Scenario`][vcjax.loops.types.Scenario] (traced data of one run),
[`Signals`][vcjax.loops.types.Signals]
(what metrics and losses read from a run) and [`GainSpec`][vcjax.loops.types.GainSpec] (one tunable
gain group)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax.environment import SeaParams, WaterMotion, Waves

__all__ = ["Scenario", "Water", "GainSpec", "Signals"]


class Scenario(NamedTuple):
    """Traced data of one run, the same container for every loop.

    Attributes:
        eta0: (n_eta,) initial generalised position (a craft's pose ``[x, y, psi]`` or
            ``[x, y, z, phi, theta, psi]``; a manipulator's joint angles) [m, rad].
        nu0: (n_nu,) initial generalised velocity (a craft's body velocity over ground).
        current: (3,) the water's velocity in NED [m/s] (the one current convention of vcjax;
            planar craft use its first two components; ignored by loops without water).
        u_d: () desired speed along the path [m/s].
        varpi0: () initial path-particle parameter.
        path: coefficients of the loop's path (kind: ``Loop.path``).
        plant: parameters of the simulated plant (the vehicle's parameter NamedTuple).
        design: parameters the *controller* believes (its design model and actuator map come
            from them); equal to ``plant`` unless a study perturbs the plant (model error).
        disturbance: (n_nu,) constant generalised disturbance force on the plant (body frame
            for craft) [N, N m]; zeros where the plant takes none.
        sea: a [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea] (``N`` regular
            components, (N,) arrays) whose
            orbital motion the plant feels on top of ``current``
            ([`Loop.plant_in_sea`][vcjax.loops.loop.Loop.plant_in_sea]), or
            ``None``: no waves. Whether it is ``None`` is static (it changes the program).
        origin_depth: () depth of the NED origin below the sea's mean free surface [m]: the sea
            is felt at depth ``origin_depth + z`` (the same mission at another survey depth);
            ``None`` is 0. Unused without a sea.
        environment: a [`vcjax.environment.Environment`][vcjax.environment.component.Environment]
            (components with their sampled
            parameters) the plant and the controller feel on top of the fields above, or
            ``None``. Its components are static (part of the tree's structure).
    """

    eta0: Any
    nu0: Any
    current: Any
    u_d: Any
    varpi0: Any
    path: Any
    plant: Any
    design: Any
    disturbance: Any
    sea: Any = None
    origin_depth: Any = None
    environment: Any = None


class Water(NamedTuple):
    """The water a plant moves in during one integration step (traced; built by
    [`vcjax.loops.simulate`][vcjax.loops.disturbances.simulate] for
    [`Loop.plant_in_sea`][vcjax.loops.loop.Loop.plant_in_sea]): a uniform current plus the
    environment's components that vary in space (kind ``"waves"``).

    Attributes:
        fields: tuple of ``(component, params, held)``: each
            [`Component`][vcjax.environment.component.Component] that varies in space, its
            parameters and
            what its process holds over this step;
        current: (3,) uniform current in NED at this time [m/s];
        current_dot: (3,) its rate [m/s^2], or ``None`` (a constant current).
    """

    fields: tuple
    current: Any
    current_dot: Any = None

    @classmethod
    def of_sea(cls, sea, origin_depth, current, current_dot=None) -> Water:
        """The water of one sea ([`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea]) whose
        NED origin is
        ``origin_depth`` [m] below the mean free surface."""
        params = SeaParams(sea, jnp.asarray(origin_depth, jnp.asarray(current).dtype))
        return cls(((Waves(), params, None),), current, current_dot)

    def waves_at(self, t, p_ned):
        """``(u (3,), a (3,))``: the share of the fields in ``at``, their velocity and
        material acceleration (advected by the current, e.g. the orbital motion of a sea,
        [`orbital_kinematics`][vcjax.environment.waves.orbital_kinematics]); ``at = (current + u,
        current_dot + a)``."""
        u = a = None
        for comp, params, held in self.fields:
            u_i, a_i = comp.water(params, held, t, p_ned, self.current)
            u, a = (u_i, a_i) if u is None else (u + u_i, a + a_i)
        if u is None:
            u = jnp.zeros_like(self.current)
            a = jnp.zeros_like(self.current)
        return u, a

    def at(self, t, p_ned) -> WaterMotion:
        """The water at the NED point ``p_ned`` (3,) [m], time ``t`` [s]: a
        [`WaterMotion`][vcjax.environment.component.WaterMotion] (velocity, current + fields
        [m/s], and material acceleration [m/s^2], (3,) each; unpacks as ``v_w, a_w``), what
        a plant's door takes."""
        return self.plus(*self.waves_at(t, p_ned))

    def plus(self, u, a) -> WaterMotion:
        """The uniform current with a field's share ``(u, a)`` (3,) on top (what ``at`` adds)."""
        v = u + self.current
        if self.current_dot is not None:
            a = a + self.current_dot
        return WaterMotion(v, a)


class GainSpec(NamedTuple):
    """One tunable gain group of a loop (static; [`tuning`][tuning] builds its parameter vector
    from these).

    Attributes:
        name: the name configs use (``[problem] tune = [...]``), e.g. ``"P_G"``, ``"depth"``.
        size: number of entries.
        get: ``get(gains) -> (size,)`` the group's value (``()`` arrays are returned as (1,)).
        set: ``set(gains, value (size,)) -> gains`` (pure; traced values allowed).
        bound: ``None`` for a positive gain (tuned as ``exp(theta)``), or ``bound(gains) ->
            (size,)``: an upper bound that depends on the *other* gains (e.g. a Routh–Hurwitz
            limit on integral gains); the gain is tuned as a fraction of it in ``[0, bound)``.
    """

    name: str
    size: int
    get: Callable
    set: Callable
    bound: Callable | None = None


class Signals(NamedTuple):
    """What the one metrics function ([`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]) and
    the tuning loss
    read from a run: N per-step samples (the state at the start of each step), true values
    (not what a noisy sensor told the controller).

    Attributes:
        eps: (N, 2) path errors ``[s, e]`` (along-, cross-track) [m].
        pos: (N, 3) NED position of what follows the path
            ([`Loop.position`][vcjax.loops.loop.Loop.position]) [m].
        p_err: (N, 3) position minus the path particle's point ``p_p(varpi)``, NED [m].
        u_err: (N,) speed error [m/s].
        psi_err: (N,) heading (or attitude) error [rad]; zeros where the law has none.
        depth_err: (N,) depth error [m]; zeros for planar loops.
        cmd_ratio: (N, A) actuator commands divided by their limits (|.| > 1: beyond).
        sat: (N,) bool, some actuator commanded at or beyond its limit.
        act: dict ``name -> (M,)`` actuator magnitudes reported as ``max_abs_<name>``.
    """

    eps: Any
    pos: Any
    p_err: Any
    u_err: Any
    psi_err: Any
    depth_err: Any
    cmd_ratio: Any
    sat: Any
    act: Any
