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
from typing import Any

import numpy as np

from vcjax._checks import float_dtype, with_options
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

__all__ = ["FitSettings", "FitResult", "fit_logs", "CORRELATION_WARN"]

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


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """Settings of [`fit_logs`][vcjax.identify.fit.fit_logs] (the ``[model]`` and ``[fit]``
    sections of a fit config, less the vehicle and the parameter names).

    Attributes:
        step: ``"pvs"`` or an integrator name.
        fit_current: also estimate the current.
        current_speed, current_direction: the known current [m/s], [rad] (or, with
            ``fit_current``, the initial guess).
        initial_scale: start every parameter at ``nominal * initial_scale``.
        segment_steps: samples per shooting segment (>= 2).
        max_iters: Levenberg-Marquardt iterations per stage.
        base: the nominal parameters (default: the vehicle's defaults in ``dtype``).
        dtype: floating-point type of the default ``base``.
        max_memory_gb: limit of the estimated memory (``fit_estimate``; default 80 % of the
            machine's).
    """

    step: str = "rk4"
    fit_current: bool = False
    current_speed: float = 0.0
    current_direction: float = 0.0
    initial_scale: float = 1.0
    segment_steps: int = 50
    max_iters: int = 50
    base: Any = None
    dtype: Any = None
    max_memory_gb: float | None = None


def _check_inputs(model: FitModel, logs, params, o: FitSettings) -> None:
    """Every argument of [`fit_logs`][vcjax.identify.fit.fit_logs] that can be checked without
    the data's content (``ValueError`` naming it)."""
    if not logs:
        raise ValueError("files: no logs given")
    if not (isinstance(o.segment_steps, int) and o.segment_steps >= 2):
        raise ValueError(f"segment_steps: expected an int >= 2, got {o.segment_steps!r}")
    if not (isinstance(o.max_iters, int) and o.max_iters >= 1):
        raise ValueError(f"max_iters: expected an int >= 1, got {o.max_iters!r}")
    if not (math.isfinite(o.initial_scale) and o.initial_scale > 0):
        raise ValueError(f"initial_scale: expected a finite value > 0, got {o.initial_scale!r}")
    if not params and not o.fit_current:
        raise ValueError("params: nothing to fit (empty list and fit_current = false)")
    for log in logs:
        if log.x.shape[1] != model.n_x or log.u.shape[1] != model.n_u:
            raise ValueError(f"{log.name}: state/command columns do not match {model.vehicle!r}")


@dataclasses.dataclass
class _Shots:
    """The segmented logs of a fit and their counts: ``spread`` (per channel standard deviation
    of every sample, 1 where constant), ``n_real`` samples, ``m`` residuals, ``n_par`` unknowns
    and the degrees-of-freedom factor ``m / (m - n_par)``."""

    seg: Any
    spread: np.ndarray
    n_real: float
    m: float
    n_par: int

    @property
    def dof_factor(self) -> float:
        return self.m / (self.m - self.n_par)

    def noise(self, r, w) -> np.ndarray:
        """(n_x,) residual standard deviation per channel of the residuals ``r`` with weights
        ``w``."""
        seg = self.seg
        sq = (r.reshape(seg.y.shape) / w) ** 2 * seg.mask[..., None]
        return np.sqrt(np.sum(sq, axis=(0, 1)) / self.n_real * self.dof_factor)


def _shots(model: FitModel, logs, o: FitSettings, n_z: int) -> _Shots:
    seg = make_segments(logs, o.segment_steps)
    spread = np.std(np.concatenate([log.x for log in logs]), axis=0)
    n_real = float(seg.mask.sum())
    m, n_par = n_real * model.n_x, n_z + seg.y.shape[0] * model.n_x
    if m - n_par <= 0:
        raise ValueError(
            f"segment_steps: {o.segment_steps} leaves no residual degrees of freedom "
            f"({int(m)} residuals for {n_par} unknowns)"
        )
    return _Shots(seg, np.where(spread > 0, spread, 1.0), n_real, m, n_par)


def _two_stages(prob: ShootingProblem, sh: _Shots, z0, max_iters: int, callback):
    """``(result, weights, cost history, iterations per stage)``: the fit with the spread
    weights, then (unless it fitted to round-off or was interrupted) with the noise weights of
    its residuals."""
    history, stage_iters = [], []
    z, s, w, seg = z0, sh.seg.y[:, 0, :], 1.0 / sh.spread, sh.seg
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
            sig = sh.noise(res.r, w)
            if np.all(sig < 1e-7 * sh.spread):
                break  # noise-free data fitted to round-off: nothing to reweight
            w = 1.0 / np.maximum(sig, 1e-12 * sh.spread)
    return res, w, history, stage_iters


def _uncertainty(prob: ShootingProblem, sh: _Shots, res):
    """``(standard deviations, correlation, normalised information)`` of the estimates (delta
    method through the parameters' scaling)."""
    sigma2 = float(np.sum(res.r**2)) / (sh.m - sh.n_par)
    info = schur_information(res.Jz, res.Js)
    d = np.sqrt(np.maximum(np.diag(info), 1e-300))
    info_n = info / np.outer(d, d)
    cov_n = np.linalg.inv(info_n + 1e-12 * np.eye(len(d)))
    cov_z = sigma2 * cov_n / np.outer(d, d)
    g = prob.scale_jacobian(res.z)
    cov = cov_z * np.outer(g, g)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(np.where(sd > 0, sd, 1.0), np.where(sd > 0, sd, 1.0))
    return sd, corr, info_n


def _excitation(prob: ShootingProblem, sh: _Shots, z0):
    """``(sensitivity, warning or None)``: is each parameter excited by the logs, and how well
    conditioned the problem is, at the start (spread weights)."""
    seg = sh.seg
    _, Jz0, Js0 = prob.linearize(z0, seg.y[:, 0, :], seg, 1.0 / sh.spread)
    info0 = schur_information(Jz0, Js0)
    sensitivity = check_excitation(prob.all_names, info0, sh.m)
    return sensitivity, conditioning_before_fit(prob.all_names, info0)


def _trust(prob: ShootingProblem, sh: _Shots, res, actuator_coeffs):
    """``(std, correlation, identifiability warnings, trust warnings)`` of the estimate."""
    names = prob.all_names
    sd, corr, info_n = _uncertainty(prob, sh, res)
    finite = bool(np.all(np.isfinite(info_n)) and np.all(np.isfinite(corr)))
    warns = _identifiability(names, corr, info_n) if finite else []
    std = {n: float(v) for n, v in zip(names, sd, strict=True)}
    estimates, nominal = prob.values(res.z), prob.values(np.zeros_like(res.z))
    untrusted = trust_warnings(
        names, estimates, nominal, std, info_n, actuator_coeffs=actuator_coeffs
    )
    return std, corr, warns, untrusted


def _ending(res, stage_iters, o: FitSettings) -> list[str]:
    """A warning when the fit was interrupted or did not converge."""
    if res.reason == "interrupted":
        return [
            f"interrupted after {sum(stage_iters)} iterations: the estimates are the last "
            "accepted iterate, not an optimum"
        ]
    if not res.converged:
        return [f"did not converge in {o.max_iters} iterations ; raise max_iters"]
    return []


def fit_logs(
    model: FitModel,
    logs: Sequence[Log],
    params: Sequence[str],
    options: FitSettings | None = None,
    *,
    callback=None,
    **kwargs,
) -> FitResult:
    """Estimate ``params`` of ``model``'s plant from ``logs`` (see the module docstring).

    Args:
        model: [`FitModel`][vcjax.identify.models.FitModel]; logs: one or more
            [`Log`][vcjax.identify.data.Log].
        params: scalar parameter names.
        options: [`FitSettings`][vcjax.identify.fit.FitSettings] (integration, current, start,
            segments, iterations, memory limit); its fields are also accepted by name
            (``step="pvs"``, ``segment_steps=25``, ...).
        callback: ``callback(stage, iteration, cost, lam)`` after every iteration.

    Raises:
        ValueError: naming the argument (before anything is compiled).
    """
    t_start = time.perf_counter()
    o = with_options(FitSettings, options, kwargs, "fit_logs")
    _check_inputs(model, logs, params, o)
    base = model.nominal(float_dtype(o.dtype)) if o.base is None else o.base
    check_logs(model, logs, base)  # time in s, uniform sampling, angles in rad: before compiling
    prob = ShootingProblem(
        model, o.step, params, base, o.fit_current, o.current_speed, o.current_direction
    )
    est = sizing.fit_estimate(
        seg_count(logs, o.segment_steps), o.segment_steps, model.n_x, len(params)
    )
    sizing.check_estimate(est, "fit", max_memory_gb=o.max_memory_gb)  # before anything is built
    z0 = prob.z_initial(o.initial_scale)
    sh = _shots(model, logs, o, z0.size)
    seg, mask, cols = sh.seg, sh.seg.mask, model.state_columns

    def phys(z, s, w):
        return prob.residuals(z, s, seg, w).reshape(seg.y.shape) / w

    rms_before = _channel_rms(phys(z0, seg.y[:, 0, :], 1.0 / sh.spread), mask, cols)
    sensitivity, before = _excitation(prob, sh, z0)
    res, w, history, stage_iters = _two_stages(prob, sh, z0, o.max_iters, callback)
    z, s = res.z, res.s
    names = prob.all_names
    std, corr, trust, untrusted = _trust(prob, sh, res, model.actuator_coeffs)
    warns = ([before] if before else []) + trust + untrusted + _ending(res, stage_iters, o)
    estimates, nominal = prob.values(z), prob.values(np.zeros_like(z))
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
        noise_std={c: float(v) for c, v in zip(cols, sh.noise(res.r, w), strict=True)},
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
        samples=int(sh.n_real),
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
