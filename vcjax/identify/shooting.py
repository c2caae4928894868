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
problem is block-arrow shaped and :mod:`vcjax.identify.lm` solves it with a Schur complement.

Parameters are on a log scale, ``theta_i = theta_nominal_i * exp(z_i)`` (the sign is kept and a
positive coefficient stays positive); with ``fit_current`` the current's speed is log-scaled too
and its direction additive [rad].

Weights: a first fit uses ``w_c = 1 / std(y_c)`` (the spread of each measured channel); the
residual RMS of each channel then estimates its noise level ``sigma_c`` and a second fit, started
from the first, uses ``w_c = 1 / sigma_c`` (so the weighted residuals have unit variance when the
model is right). The standard errors come from the Gauss–Newton covariance of that second fit,
``cov(z) = sigma^2 (J^T J)^-1`` with the segment states profiled out and
``sigma^2 = |r|^2 / (m - p - J n_x)``, mapped to the physical parameters by the delta method.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import sizing
from vcjax._checks import float_dtype
from vcjax.identify.checks import check_excitation, check_logs, trust_warnings
from vcjax.identify.data import Log
from vcjax.identify.lm import levenberg_marquardt, schur_information
from vcjax.identify.models import FitModel, current_vector, scalar_fields

__all__ = [
    "Segments",
    "make_segments",
    "ShootingProblem",
    "FitResult",
    "fit_logs",
    "CURRENT_NAMES",
]

#: Names under which a fitted current is reported.
CURRENT_NAMES = ("current_speed", "current_direction_deg")

#: |correlation| above which a pair of estimates is reported as not separately identifiable.
CORRELATION_WARN = 0.99


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
    """Number of segments :func:`make_segments` cuts ``logs`` into."""
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
        model: the :class:`~vcjax.identify.models.FitModel`.
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
        """(q,) ``d value / d z`` of :meth:`values` (diagonal), for the delta method."""
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

        self._res = jax.jit(jax.vmap(seg, in_axes=axes))
        self._lin = jax.jit(jax.vmap(jac, in_axes=axes))
        self._sim = jax.jit(self.simulate)

    def residuals(self, z, s, seg: Segments, w):
        """(J, S n_x) weighted residuals (numpy)."""
        a = self._arrays(seg, w)
        return np.asarray(self._res(jnp.asarray(z, self.dtype), jnp.asarray(s, self.dtype), *a))

    def linearize(self, z, s, seg: Segments, w):
        """Residuals and their Jacobians ``(r (J, m), Jz (J, m, q), Js (J, m, n_x))`` (numpy)."""
        a = self._arrays(seg, w)
        out = self._lin(jnp.asarray(z, self.dtype), jnp.asarray(s, self.dtype), *a)
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
            self._sim(
                jnp.asarray(z, self.dtype),
                jnp.asarray(log.x[0], self.dtype),
                jnp.asarray(log.u[:-1], self.dtype),
                jnp.asarray(np.diff(log.t), self.dtype),
            )
        )

    def _arrays(self, seg: Segments, w):
        c = lambda a: jnp.asarray(a, self.dtype)
        return c(seg.y), c(seg.u), c(seg.dt), c(seg.mask), c(w)


@dataclasses.dataclass
class FitResult:
    """What :func:`fit_logs` found (plain Python / numpy; ``to_json`` gives fit.json's content).

    Attributes:
        names: the fitted quantities (parameters, then ``current_speed``,
            ``current_direction_deg`` with ``fit_current``).
        estimates, std, initial, nominal: name -> value (current direction in degrees).
        correlation: (q, q) correlation of the estimates.
        residual_rms_before, residual_rms_after: channel -> RMS of the multiple-shooting residuals
            (physical units) at the initial guess (segments from the measured samples) and at
            the estimate.
        free_run_rms_before, free_run_rms_after: channel -> RMS of ``free run - measurement``
            over every log (free simulation from each log's first sample).
        noise_std: channel -> residual standard deviation estimated from the fit.
        cost_history: cost of every iteration of both stages (weights of each stage).
        stage_iterations: iterations of each stage run (stage 2 is skipped when stage 1 fits
            the data to round-off); iterations: their sum; converged: the last stage converged
            *and* the optimum is trustworthy (:func:`vcjax.identify.checks.trust_warnings`:
            finite, non-zero standard errors, estimates inside the plausible range, a
            well-conditioned information matrix).
        wall_time_s: seconds, including compilation.
        warnings: identifiability (and convergence) warnings.
        z: (q,) the scaled estimate; problem: the :class:`ShootingProblem`.
        s: (J, n_x) the segments' fitted initial states; weights: (n_x,) the last stage's
            residual weights (``problem.residuals(z, s, segments, weights)`` is the fitted
            residual vector); sensitivity: name -> RMS change of the weighted residuals per
            unit relative change, at the initial estimate
            (:func:`vcjax.identify.checks.sensitivities`).
    """

    names: tuple
    estimates: dict
    std: dict
    initial: dict
    nominal: dict
    correlation: np.ndarray
    residual_rms_before: dict
    residual_rms_after: dict
    free_run_rms_before: dict
    free_run_rms_after: dict
    noise_std: dict
    cost_history: list
    stage_iterations: list
    iterations: int
    converged: bool
    reason: str
    wall_time_s: float
    warnings: list
    z: np.ndarray
    z0: np.ndarray
    segments: int
    samples: int
    problem: ShootingProblem = dataclasses.field(repr=False)
    s: np.ndarray | None = None
    weights: np.ndarray | None = None
    sensitivity: dict = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        """fit.json's content: ``estimates`` is a flat {parameter: value} map (vehicle parameters
        only, so that it can be applied to a vehicle as overrides); a fitted current is reported
        under ``current``; non-finite numbers (a free run that diverged) become ``null``."""
        par = [n for n in self.names if n not in CURRENT_NAMES]
        out = {
            "vehicle": self.problem.model.vehicle,
            "step": self.problem.step_name,
            "estimates": {n: self.estimates[n] for n in par},
            "std": {n: self.std[n] for n in par},
            "initial": {n: self.initial[n] for n in par},
            "nominal": {n: self.nominal[n] for n in par},
            "correlation": {
                "names": list(self.names),
                "matrix": np.round(self.correlation, 6).tolist(),
            },
        }
        if self.problem.fit_current:
            out["current"] = {
                "estimates": {n: self.estimates[n] for n in CURRENT_NAMES},
                "std": {n: self.std[n] for n in CURRENT_NAMES},
                "initial": {n: self.initial[n] for n in CURRENT_NAMES},
            }
        units = dict(zip(self.problem.model.state_columns, self.problem.model.units, strict=True))
        out.update(
            residual_rms={"before": self.residual_rms_before, "after": self.residual_rms_after},
            free_run_rms={"before": self.free_run_rms_before, "after": self.free_run_rms_after},
            noise_std=self.noise_std,
            units=units,
            cost_history=self.cost_history,
            iterations=self.iterations,
            stage_iterations=self.stage_iterations,
            converged=self.converged,
            reason=self.reason,
            wall_time_s=round(self.wall_time_s, 3),
            segments=self.segments,
            samples=self.samples,
            warnings=self.warnings,
            sensitivity=self.sensitivity,
        )
        return _finite_or_none(out)


def _finite_or_none(tree):
    """Non-finite floats as ``None`` (strict JSON), recursively through dicts and lists."""
    if isinstance(tree, dict):
        return {k: _finite_or_none(v) for k, v in tree.items()}
    if isinstance(tree, list | tuple):
        return [_finite_or_none(v) for v in tree]
    if isinstance(tree, float) and not math.isfinite(tree):
        return None
    return tree


def _channel_rms(phys, mask, columns) -> dict[str, float]:
    """RMS per channel of (J, S, n_x) physical residuals over the real samples."""
    n = max(float(mask.sum()), 1.0)
    rms = np.sqrt(np.sum(phys**2 * mask[..., None], axis=(0, 1)) / n)
    return {c: float(v) for c, v in zip(columns, rms, strict=True)}


def _identifiability(names, corr, info_n) -> list[str]:
    """Warnings for pairs with |correlation| > 0.99 and for near-null directions."""
    out = []
    q = len(names)
    for i in range(q):
        for j in range(i + 1, q):
            if abs(corr[i, j]) > CORRELATION_WARN:
                out.append(
                    f"{names[i]} and {names[j]} are not separately identifiable from these data "
                    f"(correlation {corr[i, j]:+.4f}): only a combination of them is determined"
                )
    evals, evecs = np.linalg.eigh(info_n)
    if q > 2 and evals[0] < 1e-10 * evals[-1] and not out:
        involved = [names[i] for i in np.flatnonzero(np.abs(evecs[:, 0]) > 0.1)]
        out.append(
            f"parameters {involved} are not separately identifiable from these data "
            f"(information matrix condition number {evals[-1] / max(evals[0], 1e-300):.2g})"
        )
    return out


def fit_logs(
    model: FitModel,
    logs: Sequence[Log],
    params: Sequence[str],
    step: str = "rk4",
    fit_current: bool = False,
    current_speed: float = 0.0,
    current_direction: float = 0.0,
    initial_scale: float = 1.0,
    segment_steps: int = 50,
    max_iters: int = 50,
    base=None,
    dtype=None,
    callback=None,
    max_memory_gb: float | None = None,
) -> FitResult:
    """Estimate ``params`` of ``model``'s plant from ``logs`` (see the module docstring).

    Args:
        model: :class:`~vcjax.identify.models.FitModel`; logs: one or more :class:`Log`.
        params: scalar parameter names; step: ``"pvs"`` or an integrator name.
        fit_current: also estimate the current; current_speed [m/s], current_direction [rad]:
            the known current (or, with ``fit_current``, the initial guess).
        initial_scale: start every parameter at ``nominal * initial_scale``.
        segment_steps: samples per shooting segment (>= 2); max_iters: per stage.
        base: the nominal parameters (default: the vehicle's defaults in ``dtype``).
        callback: ``callback(stage, iteration, cost, lam)`` after every iteration.
        max_memory_gb: limit of the estimated memory (:func:`vcjax.sizing.fit_estimate`;
            default 80 % of the machine's).

    Raises:
        ValueError: naming the argument (before anything is compiled).
    """
    t_start = time.perf_counter()
    if not logs:
        raise ValueError("files: no logs given")
    if not (isinstance(segment_steps, int) and segment_steps >= 2):
        raise ValueError(f"segment_steps: expected an int >= 2, got {segment_steps!r}")
    if not (isinstance(max_iters, int) and max_iters >= 1):
        raise ValueError(f"max_iters: expected an int >= 1, got {max_iters!r}")
    if not (math.isfinite(initial_scale) and initial_scale > 0):
        raise ValueError(f"initial_scale: expected a finite value > 0, got {initial_scale!r}")
    if not params and not fit_current:
        raise ValueError("params: nothing to fit (empty list and fit_current = false)")
    for log in logs:
        if log.x.shape[1] != model.n_x or log.u.shape[1] != model.n_u:
            raise ValueError(f"{log.name}: state/command columns do not match {model.vehicle!r}")
    check_logs(model, logs)  # time in s, uniform sampling, angles in rad: before compiling
    base = model.nominal(float_dtype(dtype)) if base is None else base
    prob = ShootingProblem(model, step, params, base, fit_current, current_speed, current_direction)
    est = sizing.fit_estimate(seg_count(logs, segment_steps), segment_steps, model.n_x, len(params))
    sizing.check_estimate(est, "fit", max_memory_gb=max_memory_gb)  # before anything is built
    seg = make_segments(logs, segment_steps)
    mask = seg.mask
    cols = model.state_columns
    all_x = np.concatenate([log.x for log in logs])
    spread = np.std(all_x, axis=0)
    spread = np.where(spread > 0, spread, 1.0)

    z0 = prob.z_initial(initial_scale)
    s0 = seg.y[:, 0, :]

    def phys(z, s, w):
        return prob.residuals(z, s, seg, w).reshape(seg.y.shape) / w

    history, stage_iters = [], []
    z, s = z0, s0
    w = 1.0 / spread
    rms_before = _channel_rms(phys(z0, s0, w), mask, cols)
    n_real = float(mask.sum())
    m = n_real * model.n_x
    n_par = z0.size + seg.y.shape[0] * model.n_x
    if m - n_par <= 0:
        raise ValueError(
            f"segment_steps: {segment_steps} leaves no residual degrees of freedom "
            f"({int(m)} residuals for {n_par} unknowns)"
        )
    dof_factor = m / (m - n_par)
    _, Jz0, Js0 = prob.linearize(z0, s0, seg, w)  # each parameter excited by the logs?
    sensitivity = check_excitation(prob.all_names, schur_information(Jz0, Js0), m)
    res = None
    for stage in (1, 2):
        cb = (lambda it, c, lam, _s=stage: callback(_s, it, c, lam)) if callback else None
        res = levenberg_marquardt(
            lambda z_, s_, _w=w: prob.linearize(z_, s_, seg, _w),
            lambda z_, s_, _w=w: prob.residuals(z_, s_, seg, _w),
            z,
            s,
            max_iters=max_iters,
            callback=cb,
        )
        history += res.cost_history
        stage_iters.append(res.iterations)
        z, s = res.z, res.s
        if res.reason == "interrupted":
            break
        if stage == 1:
            sig = np.sqrt(
                np.sum((res.r.reshape(seg.y.shape) / w) ** 2 * mask[..., None], axis=(0, 1))
                / n_real
                * dof_factor
            )
            if np.all(sig < 1e-7 * spread):
                break  # noise-free data fitted to round-off: nothing to reweight
            w = 1.0 / np.maximum(sig, 1e-12 * spread)

    noise = np.sqrt(
        np.sum((res.r.reshape(seg.y.shape) / w) ** 2 * mask[..., None], axis=(0, 1))
        / n_real
        * dof_factor
    )
    sigma2 = float(np.sum(res.r**2)) / (m - n_par)
    info = schur_information(res.Jz, res.Js)
    d = np.sqrt(np.maximum(np.diag(info), 1e-300))
    info_n = info / np.outer(d, d)
    cov_n = np.linalg.inv(info_n + 1e-12 * np.eye(len(d)))
    cov_z = sigma2 * cov_n / np.outer(d, d)
    g = prob.scale_jacobian(z)
    cov = cov_z * np.outer(g, g)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(np.where(sd > 0, sd, 1.0), np.where(sd > 0, sd, 1.0))
    names = prob.all_names
    finite = bool(np.all(np.isfinite(info_n)) and np.all(np.isfinite(corr)))
    warns = _identifiability(names, corr, info_n) if finite else []
    std = {n: float(v) for n, v in zip(names, sd, strict=True)}
    estimates, nominal = prob.values(z), prob.values(np.zeros_like(z))
    untrusted = trust_warnings(names, estimates, nominal, std, info_n)
    warns += untrusted
    if res.reason == "interrupted":
        warns.append(
            f"interrupted after {sum(stage_iters)} iterations: the estimates are the last "
            "accepted iterate, not an optimum"
        )
    elif not res.converged:
        warns.append(f"did not converge in {max_iters} iterations ; raise max_iters")

    return FitResult(
        names=names,
        estimates=estimates,
        std=std,
        initial=prob.values(z0),
        nominal=nominal,
        correlation=corr,
        residual_rms_before=rms_before,
        residual_rms_after=_channel_rms(phys(z, s, w), mask, cols),
        free_run_rms_before=_free_rms(prob, z0, logs),
        free_run_rms_after=_free_rms(prob, z, logs),
        noise_std={c: float(v) for c, v in zip(cols, noise, strict=True)},
        cost_history=[float(c) for c in history],
        stage_iterations=stage_iters,
        iterations=int(sum(stage_iters)),
        converged=bool(res.converged) and not untrusted,
        reason=res.reason,
        wall_time_s=time.perf_counter() - t_start,
        warnings=warns,
        z=np.asarray(z),
        z0=np.asarray(z0),
        segments=int(seg.y.shape[0]),
        samples=int(n_real),
        problem=prob,
        s=np.asarray(s),
        weights=np.asarray(w),
        sensitivity={n: float(v) for n, v in zip(names, sensitivity, strict=True)},
    )


def _free_rms(prob: ShootingProblem, z, logs) -> dict[str, float]:
    ang = prob.model.angle_mask()
    sq, n = 0.0, 0
    for log in logs:
        d = prob.free_run(z, log) - log.x
        d[:, ang] = (d[:, ang] + np.pi) % (2 * np.pi) - np.pi
        sq = sq + np.nansum(d**2, axis=0)
        n += d.shape[0]
    rms = np.sqrt(sq / n)
    return {c: float(v) for c, v in zip(prob.model.state_columns, rms, strict=True)}
