"""The log and trust checks of ``vcjax fit`` (``vcjax.identify.checks``) at their bounds, on
tiny hand-made logs and models (numpy only: nothing is compiled), and the ``[data] [model]
[fit]`` config's declarations and checks (``vcjax.identify.config``). Exact bounds use numbers
whose arithmetic is exact in binary floating point, so that "within a factor" is tested on
the factor itself. Written for the survivors of the mutation runs of
``vcjax/identify/checks.py``, ``config.py`` and ``data.py`` (the log reader's checks and
messages; ``docs/development/testing.md``)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from vcjax.identify.checks import (
    check_excitation,
    check_logs,
    conditioning_before_fit,
    sensitivities,
    trust_warnings,
)
from vcjax.identify.config import load_fit_config, run_fit_config


def _model(cols, units, commands=(), limits=None):
    """What the checks read of a fit model: columns, units, actuator limits."""
    return SimpleNamespace(
        state_columns=tuple(cols),
        units=tuple(units),
        command_columns=tuple(commands),
        actuator_limits=None if limits is None else (lambda params: limits),
        nominal=lambda dtype: None,
    )


def _log(t, x, u=None, name="a.csv"):
    t = np.asarray(t, np.float64)
    x = np.asarray(x, np.float64).reshape(t.size, -1)
    u = np.zeros((t.size, 0)) if u is None else np.asarray(u, np.float64).reshape(t.size, -1)
    return SimpleNamespace(name=name, t=t, x=x, u=u)


# ------------------------------------------------------------------ time against the motion

PLANE = _model(("x", "y", "u", "v"), ("m", "m", "m/s", "m/s"))


def _line(slope, speed=1.0, n=41, dt=0.25):
    """A straight run along x, the positions ``x = slope t``, the logged speed ``speed``
    (exact in binary for the numbers used)."""
    t = dt * np.arange(n)
    x = np.zeros((n, 4))
    x[:, 0] = slope * t
    x[:, 2] = speed
    return _log(t, x)


@pytest.mark.parametrize(
    "slope, speed, hint",
    [
        (3.0, 1.0, None),  # exactly the factor: accepted
        (1.0, 3.0, None),  # speed 3, positions at 1 m/s: exactly 1/3, accepted
        (3.25, 1.0, ""),
        (0.25, 1.0, ""),  # a quarter of the distance: refused too
        (25.0, 1.0, ""),  # below 60 / 2: no unit named
        (30.0, 1.0, ""),  # exactly 60 / 2: not "within a factor 2" of 60
        (40.0, 1.0, "minutes"),
        (100.0, 1.0, "minutes"),
        (120.0, 1.0, ""),  # exactly 2 x 60
        (150.0, 1.0, ""),
        (3600.0, 1.0, "hours"),
        (1e-3, 1.0, "milliseconds"),
        (1e-4, 1.0, ""),
    ],
)
def test_time_against_motion_at_its_bounds_and_its_unit_hints(slope, speed, hint):
    """Refused beyond ``MAX_MOTION_RATIO`` (3) either way, the ratio in the message; the unit
    named where the ratio is within a factor 2 of 60, 3600 or 1/1000 (bounds excluded)."""
    log = _line(slope, speed)
    ratio = slope / speed
    if hint is None:
        check_logs(PLANE, [log])
        return
    with pytest.raises(ValueError, match="t must be in seconds") as e:
        check_logs(PLANE, [log])
    msg = str(e.value)
    assert f"cover {ratio:.3g} x the distance the logged speed ['u', 'v']" in msg, msg
    assert "positions ['x', 'y']" in msg
    if hint:
        k = {"minutes": 60, "hours": 3600, "milliseconds": 0.001}[hint]
        assert f"(a factor {k:g}: t looks like {hint})" in msg, msg
    assert msg.count("looks like") == bool(hint), msg


@pytest.mark.parametrize("n", [11, 39, 41])
def test_time_against_motion_compares_chords_over_a_twentieth_of_the_log(n):
    """A vehicle circling at 1 rad/s, its positions 60 x too far apart (t in minutes): the
    distance is the chord between samples ``max(1, n // 20)`` apart, the travel the arc, so
    the ratio is 60 x sin(theta / 2) / (theta / 2), theta the turn over that stride."""
    t = 0.25 * np.arange(n)
    x = np.stack([60.0 * np.sin(t), 60.0 * (1.0 - np.cos(t)), np.ones(n), np.zeros(n)], axis=1)
    half = 0.25 * max(1, n // 20) / 2.0
    with pytest.raises(ValueError, match="t looks like minutes") as e:
        check_logs(PLANE, [_log(t, x)])
    assert f"cover {60.0 * np.sin(half) / half:.3g} x" in str(e.value), e.value


def _plane(t, x, speed):
    n = np.size(t)
    x = np.asarray(x, np.float64)
    return _log(t, np.stack([x, np.zeros(n), np.broadcast_to(speed, n), np.zeros(n)], axis=1))


def test_time_against_motion_without_evidence():
    """No evidence, accepted: positions that never move (not logged), a vehicle at rest by its
    speed (a travel of at most 1e-9 m between compared samples; here exactly 1e-9), and
    position noise while at rest (only the samples that travel are compared)."""
    check_logs(PLANE, [_plane(0.25 * np.arange(41), np.zeros(41), 1.0)])
    check_logs(PLANE, [_plane(np.arange(3.0), [0.0, 1.0, 2.0], 1e-9)])
    t = 0.25 * np.arange(81)
    x = np.where(t < 10.0, 2.0 * np.random.default_rng(1).standard_normal(81), t - 10.0)
    check_logs(PLANE, [_plane(t, x, np.where(t < 10.0, 0.0, 1.0))])


def test_time_against_motion_judges_from_a_micrometre():
    """Positions covering exactly 1e-6 m in all (against 0.5 m of travel) are evidence."""
    with pytest.raises(ValueError, match=r"cover 2e-06 x the distance"):
        check_logs(PLANE, [_plane(0.25 * np.arange(3), [0.0, 1e-6, 1e-6], 1.0)])


def test_time_against_motion_needs_every_column_of_one_set():
    """Positions and velocities of one set (3-D, else the plane); without one complete set
    (here no ``v``) there is nothing to compare and a log in minutes passes."""
    model = _model(("x", "y", "z", "u", "v", "w"), ("m",) * 3 + ("m/s",) * 3)
    t = 0.25 * np.arange(41)
    x = np.zeros((41, 6))
    x[:, 1], x[:, 4] = 100.0 * t, 1.0  # along y: the 3-D set (and the plane's) sees it
    with pytest.raises(ValueError, match=r"positions \['x', 'y', 'z'\] cover 100 x"):
        check_logs(model, [_log(t, x)])
    partial = _model(("x", "y", "u"), ("m", "m", "m/s"))
    check_logs(partial, [_log(t, np.stack([100.0 * t, 0 * t, 1 + 0 * t], axis=1))])


# ------------------------------------------------------------------ sampling, angles, actuators


def _one(column, unit, values, dt=1.0, limits=None):
    """A model of one column and a log of it (no pair, no motion: only the check at hand)."""
    values = np.asarray(values, np.float64)
    model = _model((column,), (unit,), limits=limits)
    return model, _log(dt * np.arange(values.size), values)


def test_median_step_bound_and_the_milliseconds_it_suggests():
    model, log = _one("u", "m/s", np.zeros(9), dt=2.0)
    check_logs(model, [log])  # exactly MAX_STEP_S: seconds
    model, log = _one("u", "m/s", np.zeros(9), dt=2.5)
    with pytest.raises(ValueError, match=r"median time step is 2\.5 s, .* \(a step of 0\.0025 s\)"):
        check_logs(model, [log])


def test_sampling_tolerance_is_inclusive():
    """Steps of 1000/1024 s; one step longer by exactly ``SAMPLING_RTOL`` (1e-3) of it,
    1/1024 s (exact in binary, as 1e-3 x 1000/1024 rounds to it), is uniform; by 2/1024 not
    (two such steps: the first is named)."""
    steps = np.full(10, 1000.0)
    steps[5] = 1001.0
    t = np.concatenate([[0.0], np.cumsum(steps)]) / 1024.0
    model = _model(("u",), ("m/s",))
    check_logs(model, [_log(t, np.zeros(11))])
    steps[5] = steps[8] = 1002.0
    t = np.concatenate([[0.0], np.cumsum(steps)]) / 1024.0
    with pytest.raises(ValueError, match=r"2 step\(s\) differ, the first from sample 5 to 6 "):
        check_logs(model, [_log(t, np.zeros(11))])


@pytest.mark.parametrize(
    "column, unit, bound", [("theta", "rad", math.pi), ("q", "rad/s", math.pi)]
)
def test_an_angle_or_rate_of_exactly_pi_is_radians(column, unit, bound):
    values = np.zeros(9)
    values[4] = -bound
    model, log = _one(column, unit, values)
    check_logs(model, [log])
    log.x[4] = -np.nextafter(bound, 4.0)
    with pytest.raises(ValueError, match=f"column '{column}' reaches -3.142 at sample 4"):
        check_logs(model, [log])


def test_a_heading_turning_exactly_pi_per_second_is_radians():
    """Half a turn in 1 s (wrapped to -pi exactly): the bound, accepted."""
    model, log = _one("psi", "rad", np.where(np.arange(9) < 4, 0.0, math.pi))
    check_logs(model, [log])
    model, log = _one("psi", "rad", np.where(np.arange(9) < 4, 0.0, -3.0), dt=0.5)
    with pytest.raises(ValueError, match=r"'psi' turns by 3 rad in 0\.5 s at sample 3 \(6 rad/s\)"):
        check_logs(model, [log])


def test_an_actuator_at_exactly_its_margin_is_radians():
    """``ACTUATOR_MARGIN`` (1.05) x a limit of 0.5 rad: accepted; the next number refused."""
    x = np.zeros(9)
    x[3] = -1.05 * 0.5
    model, log = _one("delta", "rad", x, limits={"delta": 0.5})
    check_logs(model, [log])
    log.x[3] = -np.nextafter(1.05 * 0.5, 2.0)
    with pytest.raises(
        ValueError, match=r"'delta' reaches -0\.525 at sample 3, beyond .* 0\.5 rad"
    ):
        check_logs(model, [log])


@pytest.mark.parametrize("other", ["0.csv", "z.csv", "a.csv"])
def test_a_copy_is_named_a_copy_whatever_its_name(other):
    """A copy under a name before or after the original's is "the same data"; the same name
    "listed twice" (entries counted from 1)."""
    model = _model(("u",), ("m/s",))
    log = _log(np.arange(5.0), np.arange(5.0), name="a.csv")
    copy = _log(np.arange(5.0), np.arange(5.0), name=other)
    same = "is listed twice" if other == "a.csv" else "holds the same data as a.csv"
    with pytest.raises(ValueError, match=f"{other} \\(entry 3\\) {same} \\(entry 2\\)"):
        check_logs(model, [_log(np.arange(5.0), np.ones(5)), log, copy])


def test_only_actuator_angles_are_judged_against_their_limits():
    """Degrees are the misreading the limit catches: an actuator in another unit (a thrust in
    N, a propeller in rpm) beyond its limit is the plant's business, not refused here."""
    limits = {"thrust": 1.0, "n": 1.0, "delta": 1.0}
    model = _model(("thrust", "n", "delta"), ("N", "rpm", "rad"), limits=limits)
    x = np.zeros((9, 3))
    x[4] = [5.0, 5.0, 0.5]
    check_logs(model, [_log(np.arange(9.0), x)])
    x[4, 2] = 5.0
    with pytest.raises(ValueError, match="column 'delta' reaches 5 at sample 4"):
        check_logs(model, [_log(np.arange(9.0), x)])


# ------------------------------------------------------------------ pairs: a factor 180/pi

_DEG = 180.0 / math.pi
SERVO = _model(("delta",), ("rad",), commands=("delta_cmd",))


def _servo(delta, cmd):
    """The actuator follows the previous sample's command: ``delta[1:]`` against
    ``cmd[:-1]``."""
    return _log(np.arange(float(len(delta))), delta, cmd)


@pytest.mark.parametrize(
    "k, flagged", [(_DEG / 2.0, False), (np.nextafter(_DEG / 2.0, 99.0), True), (_DEG * 2.0, False)]
)
def test_an_actuator_pair_at_the_bounds_of_the_degree_factor(k, flagged):
    """A command exactly ``k`` x its actuator (one moving sample: the regression is exact):
    within a factor 2 of 180/pi, bounds excluded, the command is named in degrees."""
    log = _servo([0.0, 1.0, 0.0, 0.0], [k, 0.0, 0.0, 0.0])
    if not flagged:
        check_logs(SERVO, [log])
        return
    with pytest.raises(ValueError, match=r"column 'delta_cmd' is 28\.6 x 'delta' \(180/pi"):
        check_logs(SERVO, [log])


def test_a_pair_correlated_exactly_at_the_threshold_is_judged():
    """Correlation exactly ``MIN_PAIR_CORRELATION`` (0.9; 27.606359975757595 makes it so in
    binary): the pair is compared, and the factor 57 names the command in degrees."""
    log = _servo([0.0, 1.0, 0.0, 0.0], [57.0, 27.606359975757595, 0.0, 0.0])
    xa, xb = log.x[1:, 0], log.u[:-1, 0]
    assert float(np.dot(xa, xb) / np.sqrt(np.dot(xa, xa) * np.dot(xb, xb))) == 0.9
    with pytest.raises(ValueError, match=r"column 'delta_cmd' is 57 x 'delta' \(180/pi = 57\.3\)"):
        check_logs(SERVO, [log])


HEADING = _model(("psi", "r"), ("rad", "rad/s"))


def test_a_rate_pair_is_compared_over_half_a_second_of_a_noisy_wrapping_heading():
    """A heading near +-pi (wrapping) swinging with a 1.5 s period plus 1 mrad of sensor noise,
    its rate logged in deg/s: over 0.5 s the two agree (correlation ~0.99) and ``r`` is named;
    one-sample differences would be noise (~0.07 rad/s against ~0.03), and differences over
    a whole period (1.5 s) nothing but noise."""
    t = 0.02 * np.arange(301)
    w = 2 * np.pi / 1.5
    noise = 1e-3 * np.random.default_rng(5).standard_normal(t.size)
    psi = (math.pi - 0.003 + 0.01 * np.sin(w * t) + noise + np.pi) % (2 * np.pi) - np.pi
    assert psi.max() > 3.0 and psi.min() < -3.0  # it wraps
    x = np.stack([psi, _DEG * 0.01 * w * np.cos(w * t)], axis=1)
    with pytest.raises(ValueError, match=r"column 'r' is 5\d\.\d x the rate of 'psi' \(180/pi"):
        check_logs(HEADING, [_log(t, x)])


def test_a_three_sample_log_is_compared_over_its_whole_span():
    """Half a second is more than the log: the difference over its two steps. The heading in
    degrees turns as ``1e-4 i^3`` rad at sample ``i`` (0.02 s apart); the trapezoid average of
    its rate over both steps is 1.125 x the true one: the factor reads 180/pi / 1.125 = 50.9
    (step by step it would read 180/pi x 50/54 = 53.1)."""
    i = np.arange(3.0)
    x = np.stack([_DEG * 1e-4 * i**3, 3e-4 * i**2 / 0.02], axis=1)
    with pytest.raises(ValueError, match=r"the rate of column 'psi' is 50\.9 x 'r' .* 'psi' is in"):
        check_logs(HEADING, [_log(0.02 * i, x)])


# ------------------------------------------------------------------ excitation and trust


def test_sensitivities_clip_negative_information_and_divide_by_at_least_one_residual():
    info = np.diag([4.0, -1.0, 9.0])
    np.testing.assert_array_equal(sensitivities(info, 4), [1.0, 0.0, 1.5])
    np.testing.assert_array_equal(sensitivities(info, 0.5), [2.0, 0.0, 3.0])  # m < 1: as 1


@pytest.mark.parametrize(
    "b, low",
    [
        (1e-6 * 2.0, False),  # exactly MIN_RELATIVE_SENSITIVITY x the largest (2): excited
        (np.nextafter(1e-6 * 2.0, 0.0), True),
    ],
)
def test_excitation_relative_bound_is_inclusive(b, low):
    """``sqrt(fl(s^2)) == s`` in binary floating point: the sensitivities are exactly 2 and
    ``b``."""
    info = np.diag([4.0, b * b, 0.25])
    if not low:
        np.testing.assert_array_equal(check_excitation(["a", "b", "c"], info, 1), [2.0, b, 0.5])
        return
    with pytest.raises(ValueError, match=r"do not excite b \(2e-06\): .*, largest 2;"):
        check_excitation(["a", "b", "c"], info, 1)


def test_excitation_names_must_match_the_information():
    """One name for a 2 x 2 information matrix: an error, finite or not."""
    with pytest.raises(ValueError, match="zip"):
        check_excitation(["a"], np.eye(2), 1)
    with pytest.raises(ValueError, match="zip"):
        check_excitation(["a"], np.diag([1.0, np.inf]), 1)


def test_excitation_absolute_bound_is_inclusive():
    """Every sensitivity tiny but alike (no relative gap): exactly ``MIN_SENSITIVITY``
    (1e-9) is excited, the next number down is not."""
    s = 1e-9
    np.testing.assert_array_equal(check_excitation(["a"], np.diag([s * s]), 1), [s])
    low = np.nextafter(s, 0.0)
    with pytest.raises(ValueError, match=r"do not excite a \(1e-09\)"):
        check_excitation(["a"], np.diag([low * low]), 1)
    assert check_excitation([], np.zeros((0, 0)), 5).size == 0  # nothing fitted: nothing to say


def test_a_non_finite_sensitivity_names_only_its_parameter():
    with pytest.raises(ValueError, match=r"non-finite sensitivity of the residuals to \['b'\] at"):
        check_excitation(["a", "b", "c"], np.diag([1.0, np.inf, 1.0]), 10)


def _strict(f, *args, **kw):
    """``f`` with every numpy warning an error (no division by zero on the way)."""
    with warnings.catch_warnings(), np.errstate(all="raise"):
        warnings.simplefilter("error")
        return f(*args, **kw)


@pytest.mark.parametrize(
    "std, bad",
    [({"a": 0.1, "b": 0.2}, None), ({"a": 0.1}, "b: standard error None"),
     ({"a": 0.1, "b": math.nan}, "b: standard error nan"),
     ({"a": 0.1, "b": math.inf}, "b: standard error inf"),
     ({"a": 0.0, "b": 0.2}, "a: standard error 0.0: zero or non-finite")],
)  # fmt: skip
def test_trust_warnings_for_standard_errors(std, bad):
    est = nom = {"a": 1.0, "b": 2.0}
    w = _strict(trust_warnings, ["a", "b"], est, nom, std, np.eye(2))
    assert w == ([] if bad is None else [w[0]]), w
    assert bad is None or w[0].startswith(bad), w


@pytest.mark.parametrize(
    "ratio, actuator, warned",
    [
        (100.0, False, False),  # the bounds are inside the plausible range
        (0.01, False, False),
        (np.nextafter(100.0, 200.0), False, True),
        (np.nextafter(0.01, 0.0), False, True),
        (10.0, True, False),
        (0.1, True, False),
        (np.nextafter(10.0, 20.0), True, True),
        (np.nextafter(0.1, 0.0), True, True),
        (-50.0, False, False),  # the magnitude counts
        (20.0, False, False),
    ],
)
def test_plausible_range_bounds(ratio, actuator, warned):
    names = ["k", "current_speed"]
    est, nom = {"k": ratio, "current_speed": 1e6}, {"k": 1.0, "current_speed": 1.0}
    coeffs = ("k",) if actuator else ()
    w = _strict(trust_warnings, names, est, nom, {"k": 1.0, "current_speed": 1.0}, np.eye(2),
                actuator_coeffs=coeffs)  # fmt: skip
    assert bool(w) is warned, w  # the current is not on a log scale: never bounded
    if warned:
        assert len(w) == 1 and w[0].startswith(f"k: estimate {ratio:.4g} is {abs(ratio):.3g} x")
        assert ("an actuator's coefficient" in w[0]) is actuator
        assert ("(a factor pi/180 = 0.01745 on the angle): check their units" in w[0]) is actuator
    scaled = _strict(trust_warnings, names, est, nom, {"k": 1.0, "current_speed": 1.0},
                     np.eye(2), scale_names=names, actuator_coeffs=coeffs)  # fmt: skip
    assert scaled[-1].startswith("current_speed: estimate 1e+06 is 1e+06 x")


def test_estimates_without_a_nominal_or_finite_value_are_not_bounded():
    """Skipped, and the next parameter still judged."""
    names = ["a", "b", "c", "d", "e"]
    est = {"a": 1e9, "b": math.inf, "c": 1e9, "e": 1e3}
    nom = {"a": 0.0, "b": 1.0, "c": None, "d": 1.0, "e": 1.0}
    std = dict.fromkeys(names, 1.0)
    w = _strict(trust_warnings, names, est, nom, std, np.eye(5))
    assert len(w) == 1 and w[0].startswith("e: estimate 1000 is 1e+03 x its nominal value 1,"), w


@pytest.mark.parametrize(
    "info, warned",
    [
        (np.zeros((0, 0)), None),
        (np.eye(2), None),
        (np.diag([1.0, 0.0]), "poorly conditioned (condition number inf > 1e+10)"),
        (np.diag([1.0, -1.0]), "poorly conditioned (condition number inf > 1e+10)"),
        (np.diag([1e10, 1.0]), None),  # exactly MAX_CONDITION: trusted
        (np.diag([np.nextafter(1e10, 2e10), 1.0]), "poorly conditioned (condition number 1e+10"),
        (np.array([[1.0, np.nan], [np.nan, 1.0]]), "not finite: no standard errors"),
    ],
)
def test_trust_warnings_for_the_information_matrix(info, warned):
    n = ["a", "b"]
    w = _strict(trust_warnings, n, {}, {}, dict.fromkeys(n, 1.0), info)
    assert w == ([] if warned is None else [w[0]]) and (warned is None or warned in w[0]), w


def _pair(rho, scale=(2.0, 3.0)):
    """An information matrix ``S C S``: unit-diagonal ``C`` with correlation ``rho``."""
    s = np.diag(scale)
    return s @ np.array([[1.0, rho], [rho, 1.0]]) @ s


@pytest.mark.parametrize(
    "info, names, combo",
    [
        (_pair(1 - 1e-12), ["a", "b"], "1 a - 1 b"),
        (_pair(-(1 - 1e-12)), ["a", "b"], "1 a + 1 b"),
        (_pair(1 - 1e-12, (1e-3, 5e4)), ["a", "b"], "1 a - 1 b"),
        # a third, independent parameter first: not named, and the first named is positive
        (np.block([[np.eye(1), np.zeros((1, 2))], [np.zeros((2, 1)), _pair(1 - 1e-12)]]),
         ["c", "a", "b"], "1 a - 1 b"),
    ],
)  # fmt: skip
def test_conditioning_before_fit_names_the_weak_combination(info, names, combo):
    w = _strict(conditioning_before_fit, names, info)
    assert "(condition number 2e+12 > 1e+10): the logs hardly determine the combination " in w
    assert f"the combination {combo} of the relative changes" in w, w


@pytest.mark.parametrize(
    "info",
    [
        np.eye(1) * 1e-30,  # one parameter: no combination
        _pair(0.5),
        np.diag([1e10, 1.0]),  # condition 1 once normalised to unit diagonal
        np.diag([1.0, 0.0]),  # not excited (the excitation check reports it)
        np.array([[1.0, np.inf], [np.inf, 1.0]]),
    ],
)
def test_conditioning_before_fit_is_silent(info):
    assert _strict(conditioning_before_fit, ["a", "b"][: info.shape[0]], info) is None


def test_conditioning_before_fit_of_a_singular_matrix():
    """Exactly singular (two identical columns): an infinite condition number."""
    w = _strict(conditioning_before_fit, ["a", "b"], np.ones((2, 2)))
    assert "(condition number inf > 1e+10)" in w and "combination 1 a - 1 b " in w, w


def test_a_two_sample_log_is_compared_over_its_one_step():
    t = 0.02 * np.arange(2)
    x = np.stack([_DEG * 0.05 * t, np.full(2, 0.05)], axis=1)
    with pytest.raises(ValueError, match=r"the rate of column 'psi' is 57\.3 x 'r' "):
        check_logs(HEADING, [_log(t, x)])


def test_a_slow_log_is_compared_sample_to_sample():
    """Samples 1 s apart (half a second is less than a step): differences over one step. The
    heading in degrees turns as ``0.005 t^3`` rad; the trapezoid average of its rate over each
    step is 1.5 and 7.5 x 0.005 against true averages 1 and 7: the factor reads
    180/pi x 50/54 = 53.1 (over both steps at once it would read 180/pi / 1.125 = 50.9)."""
    t = np.arange(3.0)
    x = np.stack([_DEG * 0.005 * t**3, 3 * 0.005 * t**2], axis=1)
    with pytest.raises(ValueError, match=r"the rate of column 'psi' is 53\.1 x 'r' "):
        check_logs(HEADING, [_log(t, x)])


@pytest.mark.parametrize(
    "delta, cmd", [(-1e-10, -5.7e-9), (-5.7e-9, -1e-10)], ids=["actuator", "command"]
)
def test_a_pair_one_of_which_hardly_moves_is_not_judged(delta, cmd):
    """One of the pair at 1e-10 (RMS below 1e-9: not moving), the other 57 x it: no evidence
    either way, accepted."""
    check_logs(SERVO, [_servo([0.0, delta, delta, delta], [cmd, cmd, cmd, 0.0])])


@pytest.mark.parametrize(
    "delta, cmd, named",
    [(1e-9, 57e-9, "column 'delta_cmd' is 57 x 'delta'"),
     (57e-9, 1e-9, "column 'delta' is 57 x 'delta_cmd'")],
)  # fmt: skip
def test_a_pair_moving_by_exactly_1e_9_is_judged(delta, cmd, named):
    """One compared sample: the smaller of the pair has an RMS of exactly 1e-9 (the bound of
    "hardly moves", excluded): judged, and the factor 57 names the one in degrees."""
    with pytest.raises(ValueError, match=named):
        check_logs(SERVO, [_servo([0.0, delta], [cmd, 0.0])])


def test_every_pair_is_judged_after_one_without_evidence():
    """A heading and rate that never move (no evidence), then a rudder whose command is in
    degrees: still named."""
    model = _model(("psi", "r", "delta"), ("rad", "rad/s", "rad"), commands=("delta_cmd",))
    x = np.zeros((4, 3))
    x[1, 2] = 0.1
    with pytest.raises(ValueError, match="column 'delta_cmd' is 57 x 'delta'"):
        check_logs(model, [_log(np.arange(4.0), x, [5.7, 0.0, 0.0, 0.0])])


@pytest.mark.parametrize("angle, rate", [("theta", "q"), ("phi", "p")])
def test_an_angle_in_degrees_is_named_against_its_rate(angle, rate):
    """The angle in degrees (its name sorts after its rate's): "the rate of column <angle> is
    57.3 x <rate>", the angle in degrees and the rate in radians."""
    model = _model((angle, rate), ("rad", "rad/s"))
    t = 0.02 * np.arange(3)
    x = np.stack([_DEG * 0.05 * t, np.full(3, 0.05)], axis=1)
    with pytest.raises(ValueError) as e:
        check_logs(model, [_log(t, x)])
    assert f"a.csv: the rate of column '{angle}' is 57.3 x '{rate}' (180/pi = 57.3): " in str(
        e.value
    )
    assert f"'{angle}' is in degrees, '{rate}' in radians" in str(e.value)


@pytest.mark.parametrize("unit", ["deg", "turn"])
def test_a_heading_in_another_declared_unit_is_not_judged_as_radians(unit):
    """The heading check is about ``rad`` columns: a model declaring its heading in other
    units (here turning 90 per half second) is taken at its word; in ``rad`` the same kind of
    turn (1.6 rad in 0.5 s) is refused."""
    model, log = _one("psi", unit, 90.0 * np.arange(9) % 360.0, dt=0.5)
    check_logs(model, [log])
    model, log = _one("psi", "rad", 1.6 * np.arange(9), dt=0.5)
    with pytest.raises(ValueError, match="'psi' turns by 1.6 rad in 0.5 s"):
        check_logs(model, [log])


def test_a_model_whose_units_do_not_match_its_columns_is_an_error():
    with pytest.raises(ValueError, match="zip"):
        check_logs(_model(("u", "v"), ("m/s",)), [_log(np.arange(3.0), np.zeros((3, 2)))])


@pytest.mark.parametrize("k", [1.0, 2.0, 0.5, 300.0, 1.0 / 300.0])
def test_a_pair_far_from_the_degree_factor_is_accepted(k):
    """A command equal to its actuator, geared by 2 either way, or 300 x apart (beyond a
    factor 2 of 180/pi): not a pair in degrees and radians."""
    check_logs(SERVO, [_servo([0.0, 0.1, 0.2, 0.0], [0.1 * k, 0.2 * k, 0.0, 0.0])])


def test_conditioning_before_fit_names_signed_components_of_the_null_direction():
    """``C = I - u u^T`` (unit ``u``) is singular; normalised to unit diagonal
    (``D = diag(1 - u_i^2)``), its null vector is ``D^(1/2) u``. With ``u`` along
    (-0.1, 1, -0.5) that is (-0.089, 0.405, -0.399) = 0.405 x (-0.22, 1, -0.99): ``a`` below
    0.3 is not named, ``b`` (the first named) positive, ``c`` negative."""
    u = np.array([-0.1, 1.0, -0.5])
    u /= np.linalg.norm(u)
    w = u * np.sqrt(1.0 - u**2)
    np.testing.assert_allclose(w / w[1], [-0.219, 1.0, -0.986], atol=1e-3)
    msg = _strict(conditioning_before_fit, ["a", "b", "c"], np.eye(3) - np.outer(u, u))
    assert "the combination 1 b - 0.99 c of the relative changes" in msg, msg
    assert "-1 b" not in msg and "+ 0.99 c" not in msg  # a's sign does not decide
    with pytest.raises(ValueError, match="zip"):  # one name short
        conditioning_before_fit(["a", "b"], np.eye(3) - np.outer(u, u))


def test_conditioning_before_fit_of_a_rounding_negative_diagonal_is_silent():
    """A profiled information's diagonal may come out a rounding error below zero: no
    sensitivity at all there (the excitation check's business), no warning."""
    info = np.array([[1.0, 0.5], [0.5, -1e-17]])
    with np.errstate(invalid="ignore"):
        assert conditioning_before_fit(["a", "b"], info) is None


# ------------------------------------------------------------------ the [data] [model] [fit] keys

_BASE = {
    "data": 'files = ["a.csv"]',
    "model": 'vehicle = "remus100"',
    "fit": 'params = ["CL_delta_r"]',
}


def _config(tmp_path, **extra):
    """A ``vcjax fit`` config of the base keys plus ``extra`` lines per section (``None``
    drops the section's base key)."""
    text = ""
    for sec, base in _BASE.items():
        lines = [] if sec in extra and extra[sec] is None else [base] + list(extra.get(sec, ()))
        text += f"[{sec}]\n" + "".join(f"{x}\n" for x in lines)
    path = tmp_path / "fit.toml"
    path.write_text(text)
    return path


def test_fit_config_defaults(tmp_path):
    cfg = load_fit_config(_config(tmp_path))
    assert (cfg.model.step, cfg.model.current_speed, cfg.model.current_direction_deg) == (
        "rk4", 0.0, 0.0)  # fmt: skip
    assert (cfg.fit.fit_current, cfg.fit.initial_scale) == (False, 1.0)
    assert (cfg.fit.segment_steps, cfg.fit.max_iters) == (50, 50)


@pytest.mark.parametrize(
    "section, key", [("data", "files"), ("model", "vehicle"), ("fit", "params")]
)
def test_fit_config_required_keys(tmp_path, section, key):
    with pytest.raises(ValueError, match=rf"\[{section}\] {key}: required key is missing"):
        load_fit_config(_config(tmp_path, **{section: None}))


@pytest.mark.parametrize(
    "section, line, ok",
    [
        ("model", "current_speed = 0.0", True),
        ("model", "current_speed = -0.5", False),
        ("fit", "initial_scale = 0.5", True),
        ("fit", "initial_scale = 0.0", False),
        ("fit", "initial_scale = -0.5", False),
        ("fit", "segment_steps = 2", True),
        ("fit", "segment_steps = 1", False),
        ("fit", "max_iters = 1", True),
        ("fit", "max_iters = 0", False),
    ],
)
def test_fit_config_bounds(tmp_path, section, line, ok):
    path = _config(tmp_path, **{section: [line]})
    if ok:
        load_fit_config(path)
    else:
        with pytest.raises(ValueError, match=rf"\[{section}\] {line.split()[0]}"):
            load_fit_config(path)


def test_fit_config_params_once_each(tmp_path):
    path = tmp_path / "fit.toml"
    path.write_text(
        '[data]\nfiles = ["a.csv"]\n[model]\nvehicle = "remus100"\n'
        '[fit]\nparams = ["CL_delta_r", "CL_delta_r"]\n'
    )
    with pytest.raises(ValueError, match=r"\[fit\] params"):
        load_fit_config(path)


@pytest.mark.parametrize(
    "extra, message",
    [
        ({"data": ["files = []"]}, r"\[data\] files: expected a non-empty list of file names"),
        ({"data": ['files = ["a.csv", ""]']}, r"\[data\] files: expected a non-empty list"),
        ({"model": ['vehicle = "nope"']}, r"\[model\] "),
        ({"model": ['vehicle = "infante"', 'step = "pvs"'], "fit": ['params = ["Y_uudr"]']},
         r"\[model\] step: 'pvs' is not available for 'infante'; choose one of"),
        ({"model": ['step = "pvs"']}, None),
        ({"fit": ["fit_current = true"]},
         r"\[model\] current_speed: fit_current = true needs a positive initial guess"),
        ({"fit": ["fit_current = true"], "model": ["current_speed = 0.1"]}, None),
        ({"fit": ["params = []"]}, r"\[fit\] params: nothing to fit"),
        ({"fit": ["params = []", "fit_current = true"], "model": ["current_speed = 0.1"]}, None),
        ({"fit": ['params = ["CL_delta_r", "nope"]']},
         r"\[fit\] params: 'nope' is not a scalar parameter of 'remus100' \(choose from "),
    ],
)  # fmt: skip
def test_fit_config_names_and_dependent_keys(tmp_path, extra, message):
    """Each section's lines replace its base key where they set it (``files``, ``vehicle``,
    ``params``), else add to it."""
    text = ""
    for sec, base in _BASE.items():
        lines = list(extra.get(sec, ()))
        if not any(x.split()[0] == base.split()[0] for x in lines):
            lines.insert(0, base)
        text += f"[{sec}]\n" + "".join(f"{x}\n" for x in lines)
    path = tmp_path / "fit.toml"
    path.write_text(text)
    if message is None:
        load_fit_config(path)
        return
    with pytest.raises(ValueError, match=message):
        load_fit_config(path)


_CSV = Path(__file__).parent / "data" / "remus100_pvs_reference.csv"


def _run_config(tmp_path, files):
    path = tmp_path / "fit.toml"
    names = ", ".join(f'"{f}"' for f in files)
    path.write_text(
        f'[data]\nfiles = [{names}]\n[model]\nvehicle = "remus100"\n'
        '[fit]\nparams = ["CL_delta_r"]\n'
    )
    return path


@pytest.mark.parametrize("form", ["path", "parsed", "dict"])
def test_run_fit_config_refuses_an_out_that_is_a_file(tmp_path, form):
    """Before fitting (nothing compiled): the config from its path, parsed, or in its dict
    form (a run.json record) all reach the ``--out`` check."""
    path = _run_config(tmp_path, [_CSV])
    (tmp_path / "out").write_text("")
    cfg = {"path": None, "parsed": load_fit_config(path)}.get(form)
    cfg = load_fit_config(path).to_dict() if form == "dict" else cfg
    with pytest.raises(ValueError, match="--out: .* exists and is not a directory"):
        run_fit_config(path, tmp_path / "out", cfg=cfg)


def test_run_fit_config_makes_a_nested_out_before_the_log_checks(tmp_path):
    """The same log twice is refused by the checks (before anything is compiled), after
    ``--out`` and its missing parents were made."""
    path = _run_config(tmp_path, [_CSV, _CSV])
    with pytest.raises(ValueError, match="is listed twice"):
        run_fit_config(path, tmp_path / "a" / "b")
    assert (tmp_path / "a" / "b").is_dir()


@pytest.mark.slow  # a whole fit of two short logs, figures included (compiles the fit: ~10 s)
def test_run_fit_config_of_two_logs_writes_a_figure_each_and_no_progress(tmp_path, capsys):
    from vcjax.identify import get_fit_model, load_log, save_log_csv

    model = get_fit_model("remus100")
    log = load_log(_CSV, model.state_columns, model.command_columns)
    names = []
    for name, rows in (("one.csv", slice(0, 40)), ("two.csv", slice(40, 80))):
        cols = (model.state_columns, model.command_columns)
        save_log_csv(tmp_path / name, log.t[rows], log.x[rows], log.u[rows], *cols)
        names.append(name)
    path = _run_config(tmp_path, names)
    path.write_text(path.read_text() + "segment_steps = 10\nmax_iters = 2\n")
    out = run_fit_config(path, tmp_path / "out")
    assert capsys.readouterr().out == ""  # progress is off unless asked for
    assert (tmp_path / "out" / "measured_vs_predicted_one.png").is_file()
    assert (tmp_path / "out" / "measured_vs_predicted_two.png").is_file()
    assert not (tmp_path / "out" / "measured_vs_predicted.png").exists()
    assert out["fit"]["files"] == names


# ------------------------------------------------------------------ reading a CSV log


def test_csv_provenance_header_and_line_numbers(tmp_path):
    """The provenance is the first line after its ``#``; a file of only that line has no
    header; a bad row is named by its line in the file (provenance and header counted)."""
    from vcjax.identify import load_log

    path = tmp_path / "a.csv"
    path.write_text("#prov\nt,u,c\n0,1,0\n1,2,0\n")
    log = load_log(path, ("u",), ("c",))
    assert log.provenance == "prov" and log.x[:, 0].tolist() == [1.0, 2.0]
    path.write_text("#prov\n")
    with pytest.raises(ValueError, match="no header line of column names"):
        load_log(path, ("u",), ("c",))
    path.write_text("#prov\nt,u,c\n0,1,0\n1\n")
    with pytest.raises(ValueError, match="line 4 has 1 fields, the header has 3"):
        load_log(path, ("u",), ("c",))
    path.write_text("t,u,c\n0\n")
    with pytest.raises(ValueError, match="line 2 has 1 fields, the header has 3"):
        load_log(path, ("u",), ("c",))


# --------------------------------------------------------------- vcjax/identify/data.py


def _load(path):
    from vcjax.identify import load_log

    return load_log(path, ("u",), ("c",))


def _csv(tmp_path, text, name="a.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_log_is_frozen_and_a_two_sample_log_is_enough(tmp_path):
    import dataclasses

    log = _load(_csv(tmp_path, "t,u,c\n0,1,2\n0.5,1,2\n"))
    assert log.t.tolist() == [0.0, 0.5]
    with pytest.raises(dataclasses.FrozenInstanceError):
        log.t = None
    with pytest.raises(ValueError, match="at least 2 samples, got 1"):
        _load(_csv(tmp_path, "t,u,c\n0,1,2\n", "b.csv"))


def test_a_csv_row_with_more_fields_than_the_header_is_named(tmp_path):
    with pytest.raises(ValueError, match="line 3 has 4 fields, the header has 3"):
        _load(_csv(tmp_path, "t,u,c\n0,1,2\n1,1,2,9\n"))


def test_the_log_suffix_chooses_the_reader(tmp_path):
    for name in ("a.abc", "a.txt", "a.zzz"):
        with pytest.raises(ValueError, match=r"expected a \.csv or \.npz log, got '\." + name[2:]):
            _load(_csv(tmp_path, "t,u,c\n0,1,2\n1,1,2\n", name))
    with pytest.raises(ValueError, match="got 'no suffix'"):
        _load(_csv(tmp_path, "t,u,c\n0,1,2\n1,1,2\n", "log"))


def test_npz_logs_take_1d_numeric_arrays_only_and_never_unpickle(tmp_path):
    good = {"t": np.array([0.0, 1.0]), "u": np.array([1.0, 2.0]), "c": np.array([0.0, 0.0])}
    np.savez(tmp_path / "ok.npz", **good)
    assert _load(tmp_path / "ok.npz").x[:, 0].tolist() == [1.0, 2.0]
    for bad in (np.ones((2, 2)), np.float64(1.0), np.array(["a", "b"])):  # 2-D, 0-D, strings
        np.savez(tmp_path / "b.npz", **{**good, "u": bad})
        with pytest.raises(ValueError, match="'u' must be a 1-D numeric array"):
            _load(tmp_path / "b.npz")
    np.savez(tmp_path / "o.npz", **{**good, "u": np.array([{"x": 1}, None], dtype=object)})
    with pytest.raises(ValueError, match="allow_pickle"):  # numpy refuses before any unpickling
        _load(tmp_path / "o.npz")
    np.savez(tmp_path / "l.npz", **{**good, "u": np.array([1.0, 2.0, 3.0])})
    with pytest.raises(ValueError, match=r"different lengths \[2, 3\]"):
        _load(tmp_path / "l.npz")


def test_missing_columns_are_named_in_singular_and_plural(tmp_path):
    with pytest.raises(ValueError, match="missing column 'c' "):
        _load(_csv(tmp_path, "t,u\n0,1\n1,1\n"))
    with pytest.raises(ValueError, match="missing columns 'u', 'c' "):
        _load(_csv(tmp_path, "t\n0\n1\n", "b.csv"))


def test_the_first_bad_value_and_the_first_non_increasing_time_are_named(tmp_path):
    with pytest.raises(ValueError, match="2 NaN/inf or empty value.s., first at line 3"):
        _load(_csv(tmp_path, "t,u,c\n0,1,2\n1,nan,2\n2,inf,2\n"))
    # equal times are refused too, and the message names the first step back and its predecessor
    with pytest.raises(ValueError, match=r"t = 1 at line 4 follows t = 1$"):
        _load(_csv(tmp_path, "t,u,c\n0,1,2\n1,1,2\n1,1,2\n3,1,2\n2,1,2\n", "b.csv"))
    with pytest.raises(ValueError, match=r"t = 0.25 at row 2 follows t = 0.5$"):
        np.savez(
            tmp_path / "d.npz",
            t=np.array([0.0, 0.5, 0.25, 1.0, 0.75]),
            u=np.zeros(5),
            c=np.zeros(5),
        )
        _load(tmp_path / "d.npz")
