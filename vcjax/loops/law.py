"""The controller side of a loop: [`Law`][vcjax.loops.law.Law].

A vehicle's loop ([`Loop`][vcjax.loops.loop.Loop]) holds its laws in a mapping
``laws: {controller name: Law}``; the loop is the plant side (plant, actuators, sensors, the
vehicle's inner loops) and asks its law for everything that depends on the controller:

* ``default_gains(loop)`` — the gains NamedTuple (a vehicle may share one gains tuple between
  its laws, each law reading its own fields);
* ``gain_specs(loop)`` — the tunable groups (build them with
  [`gain_spec`][vcjax.loops.params.gain_spec]), ``symmetric_pairs(loop)``;
* ``validate_gains(gains)`` — eager checks run after
[`gains_from_json`][vcjax.loops.params.gains_from_json]
  (the one gains-JSON reader) has read a file;
* ``params(loop, gains, sc, design)`` — the law's traced parameters from the gains, the scenario
  and ``design``: what the loop derives from the design vehicle ``sc.design`` for its laws
  ([`Loop.law_design`][vcjax.loops.loop.Loop.law_design]: INFANTE's design model and rudder
  ratio, REMUS 100's design model at ``u_d``, ODIN's 3-DOF design model, an engine loop's
  ``sc.design`` itself). One signature for every law of every vehicle;
* ``initial_state(loop, sc)`` — the law's state at ``t = 0``;
* ``step(loop, params, t, meas, z) -> (tau, z_dot, aux)`` — one control step. What ``meas``
  holds and what ``tau`` means is the vehicle's convention, written in its loop's docstring
  (INFANTE: the measured state, ``tau = [tau_u, tau_v, tau_r]``);
* ``particle(z)`` and ``heading_error(aux)`` — what the loop's
  [`Signals`][vcjax.loops.types.Signals] read from the law's state and per-step record.

A law is a frozen dataclass (static, hashable); its fields are the law's static options. A new
law for an existing vehicle is one new file with a [`Law`][vcjax.loops.law.Law] subclass plus one
[`vcjax.loops.register_law`][vcjax.loops.registry.register_law] line.
"""

from __future__ import annotations

import dataclasses

from vcjax.loops.params import gains_from_json

__all__ = ["Law", "required", "missing_methods"]


def required(fn):
    """Mark a base-class method that a subclass must override (checked at registration)."""
    fn.__vcjax_required__ = True
    return fn


def missing_methods(cls) -> list[str]:
    """Names of the [`required`][vcjax.loops.law.required] methods ``cls`` does not override."""
    return sorted(
        name for name in dir(cls) if getattr(getattr(cls, name, None), "__vcjax_required__", False)
    )


@dataclasses.dataclass(frozen=True)
class Law:
    """One controller of a vehicle (module docstring). Subclasses override the methods marked
    *required*; the others have working defaults."""

    @required
    def default_gains(self, loop):
        """The gains NamedTuple used when none is given."""
        raise NotImplementedError(f"{type(self).__name__}.default_gains")

    @required
    def gain_specs(self, loop) -> tuple:
        """The tunable gain groups ([`GainSpec`][vcjax.loops.types.GainSpec])."""
        raise NotImplementedError(f"{type(self).__name__}.gain_specs")

    def symmetric_pairs(self, loop) -> tuple:
        """Gain entries ``(group_a, i, group_b, j)`` entering only through sum and product."""
        return ()

    def validate_gains(self, gains):
        """Eager checks of gains read from a file (raise ``ValueError`` naming the gain)."""
        return gains

    def gains_from_json(self, loop, d, base=None):
        """Gains from a JSON object with the one reader; missing entries keep ``base``."""
        base = loop.default_gains() if base is None else base
        return gains_from_json(d, base, validate=self.validate_gains)

    @required
    def params(self, loop, gains, sc, design):
        """The law's traced parameters (gains, path, ...) from ``design``, what the loop derives
        from ``sc.design`` ([`Loop.law_design`][vcjax.loops.loop.Loop.law_design])."""
        raise NotImplementedError(f"{type(self).__name__}.params")

    @required
    def initial_state(self, loop, sc):
        """The law's state at ``t = 0``."""
        raise NotImplementedError(f"{type(self).__name__}.initial_state")

    @required
    def step(self, loop, params, t, meas, z):
        """``(tau, z_dot, aux)``: one control step (conventions: the vehicle's loop)."""
        raise NotImplementedError(f"{type(self).__name__}.step")

    def particle(self, z):
        """() path-particle parameter in the law's state."""
        return z.varpi

    def heading_error(self, aux):
        """Heading (or attitude) error recorded per step [rad]."""
        return aux.psi_tilde
