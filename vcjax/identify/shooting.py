"""Parameter identification by multiple shooting through a differentiable plant.

The logs are cut into segments of ``S = segment_steps`` samples. Segment ``j`` starts from its
own initial state ``s_j`` (n_x,), initialised from the measured sample at its start, and is
simulated ``S - 1`` steps with the logged commands; its residuals compare the prediction with
the measurements at all of its ``S`` samples, the first included::

    r_j = w * (x_hat_j[k] - y[k0_j + k]),   k = 0 .. S-1,   x_hat_j[0] = s_j,
    x_hat_j[k+1] = step(theta, v_c, x_hat_j[k], u[k0_j + k], t[k0_j + k + 1] - t[k0_j + k])

(angles wrapped to (-pi, pi], ``w`` (n_x,) a weight per channel). Every sample belongs to exactly
one segment, so no measurement is used twice. Because each segment is short, a long, unstable or
chaotic log still gives a well-posed problem. The segment states ``s_j`` are estimated with the
parameters (errors in the measured initial states would otherwise bias the parameters): the
problem is block-arrow shaped and [`vcjax.identify.lm`][vcjax.identify.lm] solves it with a Schur
complement.

Parameters are on a log scale, ``theta_i = theta_nominal_i * exp(z_i)`` (the sign is kept and a
positive coefficient stays positive); with ``fit_current`` the current's speed is log-scaled too
and its direction additive [rad].

Weights: a first fit uses ``w_c = 1 / std(y_c)`` (the spread of each measured channel); the
residual RMS of each channel then estimates its noise level ``sigma_c`` and a second fit, started
from the first, uses ``w_c = 1 / sigma_c`` (so the weighted residuals have unit variance when the
model is right). The standard errors come from the Gauss–Newton covariance of that second fit,
``cov(z) = sigma^2 (J^T J)^-1`` with the segment states profiled out and
``sigma^2 = |r|^2 / (m - p - J n_x)``, mapped to the physical parameters by the delta method.

This module states the problem ([`ShootingProblem`][vcjax.identify.shooting.ShootingProblem]:
segments, scaling, residuals, free
runs); [`vcjax.identify.fit`][vcjax.identify.fit] runs the two fits and reports them
([`fit_logs`][vcjax.identify.fit.fit_logs], [`FitResult`][vcjax.identify.fit.FitResult]).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.identify.data import Log
from vcjax.identify.models import FitModel, current_vector, scalar_fields
from vcjax.runtime import compiler, programs

__all__ = ["Segments", "make_segments", "seg_count", "ShootingProblem", "CURRENT_NAMES"]

#: Names under which a fitted current is reported.
CURRENT_NAMES = ("current_speed", "current_direction_deg")


@dataclasses.dataclass(frozen=True)
class Segments:
    """Logs cut into shooting segments (numpy, float64).

    Attributes:
        y: (J, S, n_x) measured samples; u: (J, S-1, n_u) commands; dt: (J, S-1) steps [s];
        mask: (J, S) 1 for a real sample, 0 for padding (the last segment of a log);
        log_index: (J,) which log each segment comes from.
    """

    y: np.ndarray
    u: np.ndarray
    dt: np.ndarray
    mask: np.ndarray
    log_index: np.ndarray


def seg_count(logs: Sequence[Log], segment_steps: int) -> int:
    """Number of segments [`make_segments`][vcjax.identify.shooting.make_segments] cuts ``logs``
    into."""
    return sum(-(-log.t.size // int(segment_steps)) for log in logs)


def make_segments(logs: Sequence[Log], segment_steps: int) -> Segments:
    """Cut every log into segments of ``segment_steps`` samples (the last one padded)."""
    S = int(segment_steps)
    ys, us, dts, masks, idx = [], [], [], [], []
    for i, log in enumerate(logs):
        N = log.t.size
        dt = np.diff(log.t)
        for k0 in range(0, N, S):
            n = min(S, N - k0)
            take = np.minimum(np.arange(k0, k0 + S), N - 1)
            step = np.minimum(np.arange(k0, k0 + S - 1), N - 2)
            ys.append(log.x[take])
            us.append(log.u[step])
            dts.append(dt[step])
            masks.append((np.arange(S) < n).astype(np.float64))
            idx.append(i)
    return Segments(
        y=np.stack(ys),
        u=np.stack(us),
        dt=np.stack(dts),
        mask=np.stack(masks),
        log_index=np.array(idx),
    )


class ShootingProblem:
    """The multiple-shooting residuals of one vehicle, one step scheme and a set of parameters.

    Args:
        model: the [`FitModel`][vcjax.identify.models.FitModel].
        step: ``"pvs"`` or an integrator name.
        names: scalar fields of the vehicle's parameters to estimate.
        fit_current: also estimate the current's speed and direction.
        base: the vehicle's parameter NamedTuple the estimates replace fields of.
        current_speed: () [m/s]; current_direction: () [rad] (known, or the initial guess).

    Raises:
        ValueError: naming a parameter the vehicle does not have, one that is not a scalar, or
            one whose nominal value is 0 (no log scale); ``step`` when unsupported.
    """

    def __init__(
        self,
        model: FitModel,
        step: str,
        names: Sequence[str],
        base,
        fit_current: bool = False,
        current_speed: float = 0.0,
        current_direction: float = 0.0,
    ):
        names = tuple(names)
        scalars = scalar_fields(base)
        for name in names:
            if name not in scalars:
                what = "is not a scalar parameter" if name in base._fields else "is not a parameter"
                raise ValueError(
                    f"params: {name!r} {what} of vehicle {model.vehicle!r}; "
                    f"choose from {list(scalars)}"
                )
            if float(getattr(base, name)) == 0.0:
                raise ValueError(
                    f"params: {name!r} is 0 in the nominal model; "
                    "it cannot be fitted on a log scale"
                )
        if len(set(names)) != len(names):
            raise ValueError(f"params: names must be unique, got {list(names)}")
        if fit_current and not current_speed > 0:
            raise ValueError(
                "current_speed: fit_current needs a positive initial current speed, "
                f"got {current_speed}"
            )
        self.model, self.names, self.fit_current = model, names, bool(fit_current)
        self.step_name = step
        self._step = model.make_step(step)
        self.dtype = jnp.asarray(base.rho).dtype
        self.base = base
        self.theta_nominal = np.array([float(getattr(base, n)) for n in names])
        self.current0 = (float(current_speed), float(current_direction))
        self.angle = jnp.asarray(model.angle_mask())
        self._jit()

    @property
    def all_names(self) -> tuple[str, ...]:
        """The fitted quantities: the parameters, then the current's speed and direction."""
        return self.names + (CURRENT_NAMES if self.fit_current else ())

    # ---------------------------------------------------------------- parameterisation
    def physical(self, z):
        """``(vehicle_params, v_c (2,))`` at the scaled parameters ``z`` (traced)."""
        p = len(self.names)
        theta = jnp.asarray(self.theta_nominal, self.dtype) * jnp.exp(z[:p])
        params = self.base._replace(**{n: theta[i] for i, n in enumerate(self.names)})
        V, beta = (jnp.asarray(c, self.dtype) for c in self.current0)
        if self.fit_current:
            V, beta = V * jnp.exp(z[p]), beta + z[p + 1]
        return params, current_vector(V, beta)

    def values(self, z) -> dict[str, float]:
        """The physical values of ``z`` by name (current direction in degrees)."""
        z = np.asarray(z, np.float64)
        p = len(self.names)
        out = {n: float(self.theta_nominal[i] * np.exp(z[i])) for i, n in enumerate(self.names)}
        if self.fit_current:
            out["current_speed"] = self.current0[0] * math.exp(z[p])
            out["current_direction_deg"] = math.degrees(self.current0[1] + z[p + 1])
        return out

    def scale_jacobian(self, z) -> np.ndarray:
        """(q,) ``d value / d z`` of ``values`` (diagonal), for the delta method."""
        v = self.values(z)
        d = [v[n] for n in self.names]
        if self.fit_current:
            d += [v["current_speed"], math.degrees(1.0)]
        return np.array(d)

    def z_initial(self, initial_scale: float = 1.0) -> np.ndarray:
        """``z`` with every parameter at ``nominal * initial_scale`` and the given current."""
        z = np.full(len(self.names), math.log(initial_scale))
        return np.concatenate([z, np.zeros(2 if self.fit_current else 0)])

    # ---------------------------------------------------------------- simulation
    def simulate(self, z, x0, u, dt):
        """(K+1, n_x) states from ``x0`` (n_x,) over commands ``u`` (K, n_u), steps ``dt`` (K,)."""
        params, v_c = self.physical(z)

        def body(x, ud):
            x_next = self._step(params, v_c, x, ud[0], ud[1])
            return x_next, x_next

        _, xs = jax.lax.scan(body, x0, (u, dt))
        return jnp.concatenate([x0[None], xs], axis=0)

    def segment_residual(self, z, s, y, u, dt, mask, w):
        """(S n_x,) weighted residuals of one segment started from ``s`` (see module doc)."""
        d = self.simulate(z, s, u, dt) - y
        d = jnp.where(self.angle, d - 2 * jnp.pi * jnp.round(d / (2 * jnp.pi)), d)
        return (d * w * mask[:, None]).reshape(-1)

    def _jit(self):
        seg = self.segment_residual
        axes = (None, 0, 0, 0, 0, 0, None)

        def jac(z, s, y, u, dt, mask, w):
            def f(z_, s_):
                r = seg(z_, s_, y, u, dt, mask, w)
                return r, r

            (Jz, Js), r = jax.jacfwd(f, argnums=(0, 1), has_aux=True)(z, s)
            return r, Jz, Js

        self._fns = {
            "residuals": jax.vmap(seg, in_axes=axes),
            "linearize": jax.vmap(jac, in_axes=axes),
            "free_run": self.simulate,
        }
        self._res = compiler.jit(self._fns["residuals"])
        self._lin = compiler.jit(self._fns["linearize"])
        self._sim = compiler.jit(self._fns["free_run"])
        self._built: dict = {}  # (name, argument spec) -> the program from the store

    def _static(self) -> tuple:
        """What fixes the programs besides their arguments' shapes (the store's key): the
        model, the step, the fitted names and the nominal parameters they scale, the current."""
        return (self.model, self.step_name, self.names, self.base, self.fit_current, self.current0)

    def _call(self, name: str, jitted, *args):
        """``jitted(*args)``, or with the program store on (the command line) the program
        [`vcjax.runtime.programs.build`][vcjax.runtime.programs.build] gives: loaded from the
        store, not traced, when an identical fit stored it (one per argument shape)."""
        if programs.store_dir() is None:
            return jitted(*args)
        spec = (name, programs.argument_spec(args))
        if spec not in self._built:
            self._built[spec], _ = programs.build(
                f"fit:{name}", self._fns[name], self._static(), args
            )
        return self._built[spec](*args)

    def residuals(self, z, s, seg: Segments, w):
        """(J, S n_x) weighted residuals (numpy)."""
        a = self._arrays(seg, w)
        z, s = jnp.asarray(z, self.dtype), jnp.asarray(s, self.dtype)
        return np.asarray(self._call("residuals", self._res, z, s, *a))

    def linearize(self, z, s, seg: Segments, w):
        """Residuals and their Jacobians ``(r (J, m), Jz (J, m, q), Js (J, m, n_x))`` (numpy)."""
        a = self._arrays(seg, w)
        z, s = jnp.asarray(z, self.dtype), jnp.asarray(s, self.dtype)
        out = self._call("linearize", self._lin, z, s, *a)
        return tuple(np.asarray(o) for o in out)

    def cost(self, z, s, seg: Segments, w):
        """() ``0.5 |r|^2`` as a JAX function of ``z`` and ``s`` (differentiable)."""
        r = jax.vmap(self.segment_residual, in_axes=(None, 0, 0, 0, 0, 0, None))(
            z, s, *self._arrays(seg, w)
        )
        return 0.5 * jnp.sum(r * r)

    def free_run(self, z, log: Log) -> np.ndarray:
        """(N, n_x) free simulation of a whole log from its first sample (numpy)."""
        return np.asarray(
            self._call(
                "free_run",
                self._sim,
                jnp.asarray(z, self.dtype),
                jnp.asarray(log.x[0], self.dtype),
                jnp.asarray(log.u[:-1], self.dtype),
                jnp.asarray(np.diff(log.t), self.dtype),
            )
        )

    def _arrays(self, seg: Segments, w):
        c = lambda a: jnp.asarray(a, self.dtype)
        return c(seg.y), c(seg.u), c(seg.dt), c(seg.mask), c(w)
