"""What ``vcjax fit`` checks so that it does not return a confident wrong answer.

Before fitting (errors, ``ValueError`` naming the log, the column and the samples; the CLI exits
with code 2 before anything is compiled), [`check_logs`][vcjax.identify.checks.check_logs]:

* **each log once**: two logs with the same samples (a file listed twice, or a copy) would
  count every residual twice and make every standard error sqrt(2) too small;
* **time in seconds**: a median time step above ``MAX_STEP_S`` (2 s) only makes sense if
  ``t`` is in milliseconds (a 20 ms step read as 20 s), and is named as such; and the
  positions must cover the distance the logged speed gives over the time steps (within a
  factor ``MAX_MOTION_RATIO``; a log in minutes covers 60 x as much). Time is checked
  before the angles, so that minutes are not blamed on a heading turning 60 x too fast;
* **uniform sampling**: every step within ``SAMPLING_RTOL`` (0.1 %) of the median step;
  otherwise the samples around the first gap are named (a 0.24 s gap in a 0.02 s log turns
  one shooting step into a 12x longer Euler step and biases the fit);
* **angles in radians**: an angle column (unit ``rad``) other than the heading whose magnitude
  exceeds pi, a heading whose step-to-step change (wrapped) exceeds pi rad/s, or a rate column
  (unit ``rad/s``) above pi rad/s (180 deg/s) only makes sense in degrees; and small angles
  in degrees are found by consistency: a rate that is 180/pi (within a factor 2) times the
  derivative of its angle (``r`` and ``psi``, ``q`` and ``theta``, ``p`` and ``phi``;
  differences over 0.5 s, so that sensor noise does not dominate), or an actuator 180/pi times
  its command (or the other way round), names the one in degrees -- where the two move together
  (correlation above ``MIN_PAIR_CORRELATION``); a channel that hardly moves (the roll of a
  noisy REMUS 100 log) gives no evidence and is not judged;
* **actuators within their limits**: an actuator state beyond its limit (x
  ``ACTUATOR_MARGIN``; the plant saturates it there, e.g. REMUS 100's rudder at 15 deg =
  0.262 rad) is in degrees -- which also catches an actuator and its command both in degrees,
  where the pair agrees.

Before fitting, once the Jacobian is compiled,
[`check_excitation`][vcjax.identify.checks.check_excitation]: each fitted
parameter's *sensitivity* -- the RMS change of the weighted residuals per unit relative change
of the parameter, ``sqrt(I_ii / m)`` with ``I`` the Fisher information (profiled over the
segments' initial states) and ``m`` the number of residuals -- at the initial estimate. A
parameter whose sensitivity is below ``MIN_SENSITIVITY`` (absolute) or
``MIN_RELATIVE_SENSITIVITY`` x the largest one is not excited by the logs: an error naming
it (a log without excitation, all zeros, cannot estimate a rudder coefficient). Then
[`conditioning_before_fit`][vcjax.identify.checks.conditioning_before_fit]: the information matrix's
condition number (unit diagonal) at
the initial estimate; above ``MAX_CONDITION`` a warning names the combination of parameters
the logs hardly determine (the weakest eigenvector's main components: ``A_r`` and
``CL_delta_r`` entering only as a product). A warning, not a refusal: the fit may move to where
the data do separate them, and the same check after fitting decides whether it is trusted.

After fitting, [`trust_warnings`][vcjax.identify.checks.trust_warnings]: a zero or non-finite
standard error, an estimate outside
the plausible range (more than a factor ``PLAUSIBLE_FACTOR`` from the nominal value: the fit
runs on a log scale, so this is its bound; for a coefficient of an actuator's angle,
``FitModel.actuator_coeffs``, a factor ``ACTUATOR_PLAUSIBLE_FACTOR``: an actuator logged in
degrees scales it by about pi/180), or an information matrix whose condition number
(normalised to unit diagonal) exceeds ``MAX_CONDITION`` is a warning, and the fit is marked
``converged: false`` (the optimum is not trustworthy).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "MAX_CONDITION",
    "MAX_STEP_S",
    "MIN_RELATIVE_SENSITIVITY",
    "MIN_SENSITIVITY",
    "PLAUSIBLE_FACTOR",
    "SAMPLING_RTOL",
    "check_excitation",
    "ACTUATOR_MARGIN",
    "ACTUATOR_PLAUSIBLE_FACTOR",
    "MAX_MOTION_RATIO",
    "check_logs",
    "conditioning_before_fit",
    "sensitivities",
    "trust_warnings",
]

#: A median time step above this [s] means ``t`` is not in seconds.
MAX_STEP_S = 2.0
#: Relative tolerance of every time step against the median step.
SAMPLING_RTOL = 1e-3
#: Angles (other than the heading) beyond this [rad], and rates beyond this [rad/s], are degrees.
MAX_ANGLE = math.pi
MAX_RATE = math.pi
#: Sensitivities (see the module docstring) below this are "not excited".
MIN_SENSITIVITY = 1e-9
MIN_RELATIVE_SENSITIVITY = 1e-6
#: Estimates more than this factor from the nominal value are at the plausible range's bound.
PLAUSIBLE_FACTOR = 100.0
#: Condition number (unit-diagonal information matrix) above which the fit is not trusted.
MAX_CONDITION = 1e10
#: Logged actuator states may exceed their limit by this factor (sensor noise) before they are
#: read as degrees.
ACTUATOR_MARGIN = 1.05
#: Estimates of an actuator's coefficient
#: ([`FitModel.actuator_coeffs`][vcjax.identify.FitModel.actuator_coeffs]) more than this
#: factor from the nominal value are not trusted: an actuator logged in degrees scales it by
#: pi/180 = 1/57.3 (or, through saturating commands, by less).
ACTUATOR_PLAUSIBLE_FACTOR = 10.0

_HEADINGS = ("psi",)


def check_logs(model, logs: Sequence, params=None) -> None:
    """Raise ``ValueError`` for the same log given twice, a log whose time is not in seconds,
    whose sampling is not uniform, or whose angles / rates only make sense in degrees (see the
    module docstring). Time is checked before angles, so that a time in minutes is named as
    such, not as a heading that turns 60 x too fast. ``params``: the vehicle's parameters whose
    actuator limits bound the logged actuators (default: its nominal ones)."""
    _check_duplicates(logs)
    for log in logs:
        _check_time(log)
        _check_time_against_motion(model, log)
        _check_units(model, log)
        _check_pairs(model, log)  # names which of a pair is in degrees, so before the limits
        _check_actuators(model, log, params)


def _check_duplicates(logs: Sequence) -> None:
    """Two logs with the same samples (one file listed twice, or a copy): each residual would be
    counted twice and every standard error come out sqrt(2) too small."""
    seen: dict = {}
    for i, log in enumerate(logs):
        key = (log.t.tobytes(), log.x.tobytes(), log.u.tobytes())
        if key in seen:
            j = seen[key]
            same = (
                "is listed twice"
                if logs[j].name == log.name
                else f"holds the same data as {logs[j].name}"
            )
            raise ValueError(
                f"files: {log.name} (entry {i + 1}) {same} (entry {j + 1}): its samples would "
                "count twice and every standard error come out sqrt(2) too small; list each "
                "log once"
            )
        seen[key] = i


#: (position, velocity) columns: the distance covered between samples against the logged speed
#: (body velocities: their norm is the speed over ground, whatever the attitude).
_MOTION = ((("x", "y", "z"), ("u", "v", "w")), (("x", "y"), ("u", "v")))
#: The distance covered over the logged speed x time beyond this factor (or below its inverse):
#: ``t`` is not in seconds.
MAX_MOTION_RATIO = 3.0


def _check_time_against_motion(model, log) -> None:
    """The positions must move as fast as the logged velocities say, in seconds: a log in
    minutes covers 60 x the distance its speed gives over its time steps."""
    cols = {c: log.x[:, j] for j, c in enumerate(model.state_columns)}
    for pos, vel in _MOTION:
        if all(c in cols for c in pos + vel):
            break
    else:
        return
    n = log.t.size
    stride = max(1, n // 20)
    p = np.stack([cols[c] for c in pos], axis=1)
    speed = np.sqrt(sum(cols[c] ** 2 for c in vel))
    dist = np.linalg.norm(p[stride:] - p[:-stride], axis=1)
    integral = np.cumsum(np.concatenate([[0.0], 0.5 * (speed[1:] + speed[:-1]) * np.diff(log.t)]))
    travel = integral[stride:] - integral[:-stride]
    moving = travel > 1e-9
    if not np.any(moving) or float(np.sum(dist[moving])) < 1e-6:
        return  # no motion: no evidence
    ratio = float(np.sum(dist[moving]) / np.sum(travel[moving]))
    if ratio > MAX_MOTION_RATIO or ratio < 1.0 / MAX_MOTION_RATIO:
        hint = ""
        for k, unit in ((60.0, "minutes"), (3600.0, "hours"), (1e-3, "milliseconds")):
            if k / 2.0 < ratio < 2.0 * k:
                hint = f" (a factor {k:g}: t looks like {unit})"
        raise ValueError(
            f"{log.name}: column 't': the positions {list(pos)} cover {ratio:.3g} x the distance "
            f"the logged speed {list(vel)} gives over the time steps{hint}; t must be in seconds"
        )


def _check_actuators(model, log, params=None) -> None:
    """An actuator state beyond its limit (the plant saturates it there): in degrees."""
    if model.actuator_limits is None:
        return
    params = model.nominal(np.float64) if params is None else params
    limits = {c: float(v) for c, v in model.actuator_limits(params).items()}
    for j, (c, unit) in enumerate(zip(model.state_columns, model.units, strict=True)):
        if c not in limits or unit != "rad":
            continue
        x = log.x[:, j]
        k = int(np.argmax(np.abs(x)))
        lim = limits[c]
        if abs(x[k]) > ACTUATOR_MARGIN * lim:
            raise ValueError(
                f"{log.name}: column {c!r} reaches {x[k]:.4g} at sample {k}, beyond the "
                f"actuator's limit of {lim:.4g} rad ({math.degrees(lim):.3g} deg) where the plant "
                "saturates it: only plausible in degrees; actuator angles must be in rad"
            )


#: (angle, its rate) and (actuator, its command) column pairs: one of a pair in degrees and the
#: other in radians shows as a factor 180/pi between them.
_RATE_PAIRS = (("psi", "r"), ("theta", "q"), ("phi", "p"))
_VALUE_PAIRS = (("delta_r", "delta_r_cmd"), ("delta_s", "delta_s_cmd"), ("delta", "delta_cmd"))
_DEG = 180.0 / math.pi
#: Correlation (about zero) above which a pair is compared at all.
MIN_PAIR_CORRELATION = 0.9


def _check_pairs(model, log) -> None:
    """A rate about 57 x (or 1/57 x) the derivative of its angle, or an actuator about 57 x its
    command (or 1/57 x): one of the pair is in degrees."""
    cols = {c: log.x[:, j] for j, c in enumerate(model.state_columns)}
    cols.update({c: log.u[:, j] for j, c in enumerate(model.command_columns)})
    # differences over ~0.5 s (not one sample): sensor noise on the angle would dominate
    n = log.t.size
    stride = int(min(max(1, round(0.5 / float(np.median(np.diff(log.t))))), max(1, n - 1)))
    span = log.t[stride:] - log.t[:-stride]
    pairs = []
    for a, b in _RATE_PAIRS:
        if a in cols and b in cols:
            d = (cols[a][stride:] - cols[a][:-stride] + math.pi) % (2 * math.pi) - math.pi
            c = np.cumsum(np.concatenate([[0.0], 0.5 * (cols[b][1:] + cols[b][:-1])]))
            mean_rate = (c[stride:] - c[:-stride]) / stride  # the rate averaged over the span
            pairs.append((a, b, d / span, mean_rate, "the rate of"))
    for a, b in _VALUE_PAIRS:
        if a in cols and b in cols:
            pairs.append((a, b, cols[a][1:], cols[b][:-1], ""))
    for a, b, xa, xb, what in pairs:
        if np.sqrt(np.mean(xa**2)) < 1e-9 or np.sqrt(np.mean(xb**2)) < 1e-9:
            continue  # nothing moves: no evidence either way
        corr = float(np.dot(xa, xb) / np.sqrt(np.dot(xa, xa) * np.dot(xb, xb)))
        if corr < MIN_PAIR_CORRELATION:
            continue  # they do not move together (noise, other terms): no evidence
        k = float(np.dot(xa, xb) / np.dot(xa, xa))  # xb ~ k xa
        for ratio, deg in ((k, b), (1.0 / k if k else math.inf, a)):
            if _DEG / 2.0 < ratio < _DEG * 2.0:
                other = a if deg == b else b
                if deg == b:
                    rel = f"column {b!r} is {ratio:.3g} x {what + ' ' if what else ''}{a!r}"
                else:
                    rel = f"{what + ' ' if what else ''}column {a!r} is {ratio:.3g} x {b!r}"
                raise ValueError(
                    f"{log.name}: {rel} (180/pi = 57.3): {deg!r} is in degrees, {other!r} in "
                    "radians; angles must be in rad and rates in rad/s"
                )


def _check_time(log) -> None:
    dt = np.diff(log.t)
    h = float(np.median(dt))
    if h > MAX_STEP_S:
        raise ValueError(
            f"{log.name}: column 't': the median time step is {h:g} s, which only makes sense "
            f"if t is in milliseconds (a step of {h / 1000:g} s); t must be in seconds"
        )
    bad = np.flatnonzero(np.abs(dt - h) > SAMPLING_RTOL * h)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{log.name}: column 't': sampling is not uniform: the step is {h:g} s, but "
            f"{bad.size} step(s) differ, the first from sample {i} to {i + 1} (data rows "
            f"{i + 1} and {i + 2}; t = {log.t[i]:g} -> {log.t[i + 1]:g} s, a step of "
            f"{dt[i]:g} s); resample the log or split it at the gap"
        )


def _check_units(model, log) -> None:
    dt = np.diff(log.t)
    for j, (c, unit) in enumerate(zip(model.state_columns, model.units, strict=True)):
        x = log.x[:, j]
        if unit == "rad" and c in _HEADINGS:
            d = (np.diff(x) + math.pi) % (2 * math.pi) - math.pi
            rate = np.abs(d) / dt
            k = int(np.argmax(rate)) if rate.size else 0
            if rate.size and rate[k] > MAX_RATE:
                raise ValueError(
                    f"{log.name}: column {c!r} turns by {abs(d[k]):.3g} rad in {dt[k]:g} s at "
                    f"sample {k} ({rate[k]:.3g} rad/s): only plausible in degrees; angles "
                    "must be in rad"
                )
        elif unit == "rad":
            k = int(np.argmax(np.abs(x)))
            if abs(x[k]) > MAX_ANGLE:
                raise ValueError(
                    f"{log.name}: column {c!r} reaches {x[k]:.4g} at sample {k}: an angle beyond "
                    "pi rad only makes sense in degrees; angles must be in rad"
                )
        elif unit == "rad/s":
            k = int(np.argmax(np.abs(x)))
            if abs(x[k]) > MAX_RATE:
                raise ValueError(
                    f"{log.name}: column {c!r} reaches {x[k]:.4g} at sample {k}: a rate beyond "
                    "pi rad/s (180 deg/s) only makes sense in deg/s; rates must be in rad/s"
                )


def sensitivities(info: np.ndarray, m: float) -> np.ndarray:
    """``sqrt(I_ii / m)``: the RMS change of the ``m`` weighted residuals per unit relative
    change of each parameter (``info``: the profiled Fisher information, log-scale
    parameters)."""
    return np.sqrt(np.maximum(np.diag(np.asarray(info, np.float64)), 0.0) / max(float(m), 1.0))


def check_excitation(names: Sequence[str], info: np.ndarray, m: float) -> np.ndarray:
    """Raise ``ValueError`` naming the parameters the logs do not excite; returns the
    sensitivities ([`sensitivities`][vcjax.identify.checks.sensitivities])."""
    sens = sensitivities(info, m)
    top = float(np.max(sens)) if sens.size else 0.0
    if not np.all(np.isfinite(sens)):
        bad = [n for n, s in zip(names, sens, strict=True) if not np.isfinite(s)]
        raise ValueError(
            f"[fit] params: non-finite sensitivity of the residuals to {bad} at the initial "
            "estimate (the model blows up on these logs: check their units)"
        )
    low = [
        (n, float(s))
        for n, s in zip(names, sens, strict=True)
        if s < MIN_SENSITIVITY or s < MIN_RELATIVE_SENSITIVITY * top
    ]
    if low:
        listed = ", ".join(f"{n} ({s:.2g})" for n, s in low)
        raise ValueError(
            f"[fit] params: the logs do not excite {listed}: sensitivity of the residuals to a "
            f"relative change, largest {top:.2g}; these cannot be estimated from these data: "
            "remove them from [fit] params or log manoeuvres that move them"
        )
    return sens


def conditioning_before_fit(names: Sequence[str], info: np.ndarray) -> str | None:
    """A warning when the Fisher information at the initial estimate, normalised to unit
    diagonal, has a condition number above ``MAX_CONDITION`` (or is singular): names the
    parameters that carry the weakest direction (eigenvector components of at least 0.3 in
    magnitude, with their signs); ``None`` when it is well conditioned or not finite (the
    excitation check reports that)."""
    info = np.asarray(info, np.float64)
    if info.shape[0] < 2 or not np.all(np.isfinite(info)):
        return None
    d = np.sqrt(np.diag(info))
    if not np.all(d > 0):
        return None
    ev, vec = np.linalg.eigh(info / np.outer(d, d))
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
    if cond <= MAX_CONDITION:
        return None
    v = vec[:, 0] / np.max(np.abs(vec[:, 0]))
    v = v * np.sign(v[np.flatnonzero(np.abs(v) >= 0.3)[0]])  # the first one named positive
    combo = " ".join(
        f"{'+' if c > 0 else '-'} {abs(c):.2g} {n}"
        for n, c in zip(names, v, strict=True)
        if abs(c) >= 0.3
    )
    return (
        f"before fitting: the information matrix at the initial estimate is poorly conditioned "
        f"(condition number {cond:.3g} > {MAX_CONDITION:.0e}): the logs hardly determine the "
        f"combination {combo.lstrip('+ ')} of the relative changes (a parameter that enters "
        "only through a product or a sum with another cannot be separated from it)"
    )


def trust_warnings(
    names: Sequence[str],
    estimates: dict,
    nominal: dict,
    std: dict,
    info_n: np.ndarray,
    scale_names: Sequence[str] | None = None,
    actuator_coeffs: Sequence[str] = (),
) -> list[str]:
    """Warnings that make an optimum untrustworthy (see the module docstring); empty when the
    fit can be trusted. ``scale_names``: the parameters fitted on a log scale (default all
    but the current's); ``actuator_coeffs``: those that multiply an actuator's angle (a
    narrower plausible range, ``ACTUATOR_PLAUSIBLE_FACTOR``)."""
    out = []
    for n in names:
        s = std.get(n)
        if s is None or not math.isfinite(s) or s == 0.0:
            out.append(
                f"{n}: standard error {s}: zero or non-finite, so the data do not determine "
                "its uncertainty (the estimate is not trustworthy)"
            )
    scale_names = (
        [n for n in names if not n.startswith("current")] if scale_names is None else scale_names
    )
    for n in scale_names:
        e, nom = estimates.get(n), nominal.get(n)
        if e is None or nom in (None, 0.0) or not math.isfinite(e):
            continue
        ratio = abs(e / nom)
        if n in actuator_coeffs and not (
            1.0 / ACTUATOR_PLAUSIBLE_FACTOR <= ratio <= ACTUATOR_PLAUSIBLE_FACTOR
        ):
            out.append(
                f"{n}: estimate {e:.4g} is {ratio:.3g} x its nominal value {nom:.4g}: an "
                f"actuator's coefficient more than a factor {ACTUATOR_PLAUSIBLE_FACTOR:g} from "
                "nominal is implausible; an actuator and its command logged in degrees give "
                f"this (a factor pi/180 = {math.pi / 180:.4g} on the angle): check their units"
            )
        elif not (1.0 / PLAUSIBLE_FACTOR <= ratio <= PLAUSIBLE_FACTOR):
            out.append(
                f"{n}: estimate {e:.4g} is {ratio:.3g} x its nominal value {nom:.4g}, at the "
                f"bound of the plausible range (a factor {PLAUSIBLE_FACTOR:g} either way)"
            )
    info_n = np.asarray(info_n, np.float64)
    if info_n.size:
        if not np.all(np.isfinite(info_n)):
            out.append("the information matrix is not finite: no standard errors")
        else:
            ev = np.linalg.eigvalsh(info_n)
            cond = float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
            if cond > MAX_CONDITION:
                out.append(
                    f"the information matrix is poorly conditioned (condition number "
                    f"{cond:.3g} > {MAX_CONDITION:.0e}): some combination of {list(names)} is "
                    "not determined by these data"
                )
    return out
