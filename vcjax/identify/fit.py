"""Fitting logs by multiple shooting ([`vcjax.identify.shooting`][vcjax.identify.shooting] states
the problem): the
two Levenberg–Marquardt fits (spread weights, then noise weights), standard errors by the delta
method, identifiability and trust warnings, and the result
([`FitResult`][vcjax.identify.fit.FitResult], ``fit.json``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np

from vcjax._checks import float_dtype
from vcjax.identify.checks import (
    check_excitation,
    check_logs,
    conditioning_before_fit,
    trust_warnings,
)
from vcjax.identify.data import Log
from vcjax.identify.lm import levenberg_marquardt, schur_information
from vcjax.identify.models import FitModel
from vcjax.identify.shooting import CURRENT_NAMES, ShootingProblem, make_segments, seg_count
from vcjax.runtime import sizing

__all__ = ["FitResult", "fit_logs", "CORRELATION_WARN"]

#: |correlation| above which a pair of estimates is reported as not separately identifiable.
CORRELATION_WARN = 0.99


@dataclasses.dataclass
class FitResult:
    """What [`fit_logs`][vcjax.identify.fit.fit_logs] found (plain Python / numpy; ``to_json`` gives
    fit.json's content).

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
            *and* the optimum is trustworthy
            ([`trust_warnings`][vcjax.identify.checks.trust_warnings]:
            finite, non-zero standard errors, estimates inside the plausible range, a
            well-conditioned information matrix).
        wall_time_s: seconds, including compilation.
        warnings: identifiability (and convergence) warnings.
        z: (q,) the scaled estimate; problem: the
            [`ShootingProblem`][vcjax.identify.shooting.ShootingProblem].
        s: (J, n_x) the segments' fitted initial states; weights: (n_x,) the last stage's
            residual weights (``problem.residuals(z, s, segments, weights)`` is the fitted
            residual vector); sensitivity: name -> RMS change of the weighted residuals per
            unit relative change, at the initial estimate
            ([`sensitivities`][vcjax.identify.checks.sensitivities]).
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
        model: [`FitModel`][vcjax.identify.models.FitModel]; logs: one or more
            [`Log`][vcjax.identify.data.Log].
        params: scalar parameter names; step: ``"pvs"`` or an integrator name.
        fit_current: also estimate the current; current_speed [m/s], current_direction [rad]:
            the known current (or, with ``fit_current``, the initial guess).
        initial_scale: start every parameter at ``nominal * initial_scale``.
        segment_steps: samples per shooting segment (>= 2); max_iters: per stage.
        base: the nominal parameters (default: the vehicle's defaults in ``dtype``).
        callback: ``callback(stage, iteration, cost, lam)`` after every iteration.
        max_memory_gb: limit of the estimated memory (``fit_estimate``;
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
    base = model.nominal(float_dtype(dtype)) if base is None else base
    check_logs(model, logs, base)  # time in s, uniform sampling, angles in rad: before compiling
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
    info0 = schur_information(Jz0, Js0)
    sensitivity = check_excitation(prob.all_names, info0, m)
    before = conditioning_before_fit(prob.all_names, info0)
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
    warns = [before] if before else []
    warns += _identifiability(names, corr, info_n) if finite else []
    std = {n: float(v) for n, v in zip(names, sd, strict=True)}
    estimates, nominal = prob.values(z), prob.values(np.zeros_like(z))
    untrusted = trust_warnings(
        names, estimates, nominal, std, info_n, actuator_coeffs=model.actuator_coeffs
    )
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
