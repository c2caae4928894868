"""``vcjax fit`` does not return confident wrong answers (issue 24): excitation checked before
fitting, untrustworthy optima flagged after it, and the reported standard errors checked against
an independent ``sigma^2 (J^T J)^-1`` from a finite-difference Jacobian of the whole
multiple-shooting problem (parameters and segment states, dense, numpy).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from vcjax.cli import main
from vcjax.identify import fit_logs, get_fit_model, load_log, make_segments, save_log_csv
from vcjax.identify.checks import (
    MAX_CONDITION,
    MIN_PAIR_CORRELATION,
    check_excitation,
    check_logs,
    sensitivities,
    trust_warnings,
)

CSV = Path(__file__).parent / "data" / "remus100_pvs_reference.csv"
REMUS = get_fit_model("remus100")
CURRENT = dict(current_speed=0.5, current_direction=math.radians(170.0))


def _log(n):
    log = load_log(CSV, REMUS.state_columns, REMUS.command_columns)
    return dataclasses.replace(log, t=log.t[:n], x=log.x[:n], u=log.u[:n])


def test_a_pair_that_does_not_move_together_gives_no_evidence_of_degrees():
    """A rudder command 57.3 x the rudder plus 1.3 times as much noise: the regression ratio is
    180/pi but the two hardly move together (correlation about zero ~0.6), so the pair says
    nothing about units and the log passes; the same command without the noise is refused."""
    log = _log(600)
    i, j = REMUS.state_columns.index("delta_r"), REMUS.command_columns.index("delta_r_cmd")
    xa = log.x[1:, i]  # the actuator follows the previous sample's command
    scale = 57.3 * np.sqrt(np.mean(xa**2))
    noise = 1.3 * scale * np.random.default_rng(0).standard_normal(xa.size)
    u = log.u.copy()
    u[:-1, j] = 57.3 * xa + noise
    xb = u[:-1, j]
    corr, k = xa @ xb / np.sqrt((xa @ xa) * (xb @ xb)), xa @ xb / (xa @ xa)
    assert corr < MIN_PAIR_CORRELATION and 90.0 / np.pi < k < 360.0 / np.pi, (corr, k)
    check_logs(REMUS, [dataclasses.replace(log, u=u)])
    u[:-1, j] = 57.3 * xa
    with pytest.raises(ValueError, match="'delta_r_cmd' is in degrees"):
        check_logs(REMUS, [dataclasses.replace(log, u=u)])


# ------------------------------------------------------------------ excitation (before fitting)


def test_all_zero_log_is_refused_naming_every_parameter(tmp_path, capsys):
    """The issue's log without excitation (all zeros): refused, not 'converged' at 9e6."""
    log = _log(101)
    path = save_log_csv(
        tmp_path / "zeros.csv",
        log.t,
        np.zeros_like(log.x),
        np.zeros_like(log.u),
        REMUS.state_columns,
        REMUS.command_columns,
    )
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{path}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        '[fit]\nparams = ["CD_0", "CL_delta_r"]\nsegment_steps = 25\n'
    )
    out = tmp_path / "out"
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "vcjax: fit: [fit] params: the logs do not excite CD_0 (0), CL_delta_r (0)" in err
    assert "Traceback" not in err and not (out / "fit.json").exists()


def test_check_excitation_names_the_weak_parameter():
    info = np.diag([4.0, 1e-14, 9.0])
    with pytest.raises(ValueError, match=r"do not excite b \(1e-07\)"):
        check_excitation(["a", "b", "c"], info, m=1.0)
    np.testing.assert_allclose(sensitivities(info, 4.0), [1.0, 5e-8, 1.5])
    assert check_excitation(["a", "c"], np.diag([4.0, 9.0]), 1.0).tolist() == [2.0, 3.0]
    with pytest.raises(ValueError, match="non-finite sensitivity"):
        check_excitation(["a"], np.array([[np.nan]]), 1.0)


# ------------------------------------------------------------------ trust (after fitting)


@pytest.mark.parametrize(
    "std, est, info, message",
    [
        ({"a": 0.0}, {"a": 1.0}, np.eye(1), "a: standard error 0.0: zero or non-finite"),
        ({"a": math.nan}, {"a": 1.0}, np.eye(1), "a: standard error nan"),
        ({"a": None}, {"a": 1.0}, np.eye(1), "a: standard error None"),
        ({"a": 0.1}, {"a": 150.0}, np.eye(1), "a: estimate 150 is 150 x its nominal value 1"),
        ({"a": 0.1}, {"a": 0.005}, np.eye(1), "at the bound of the plausible range"),
        ({"a": 0.1}, {"a": 1.0}, np.array([[np.inf]]), "information matrix is not finite"),
    ],
)
def test_trust_warnings(std, est, info, message):
    w = trust_warnings(["a"], est, {"a": 1.0}, std, info)
    assert len(w) == 1 and message in w[0]


def test_trust_warnings_conditioning_and_clean_case():
    a = 1.0 - 1e-11
    ill = np.array([[1.0, a], [a, 1.0]])  # condition number ~2e11
    w = trust_warnings(["a", "b"], {"a": 1, "b": 1}, {"a": 1, "b": 1}, {"a": 1, "b": 1}, ill)
    assert len(w) == 1 and f"> {MAX_CONDITION:.0e}" in w[0] and "poorly conditioned" in w[0]
    ok = trust_warnings(["a", "b"], {"a": 1, "b": 2}, {"a": 1, "b": 1}, {"a": 1, "b": 1}, np.eye(2))
    assert ok == []
    # no information (an eigenvalue 0 or below): an infinite condition number, not 0/0 or < 0
    for singular in (0 * ill, np.diag([1.0, -1e-12])):  # the second: round-off below zero
        w = trust_warnings(
            ["a", "b"], {"a": 1, "b": 1}, {"a": 1, "b": 1}, {"a": 1, "b": 1}, singular
        )
        assert len(w) == 1 and "condition number inf" in w[0]


def test_product_pair_is_not_converged_and_warned_in_fit_json(tmp_path, capsys):
    """A_r and CL_delta_r enter only as a product: the information matrix is singular, so the
    fit is marked converged: false (the optimum is not unique), with the warning on stderr."""
    res = fit_logs(
        REMUS, [_log(201)], ["A_r", "CL_delta_r"], step="pvs", initial_scale=1.2,
        segment_steps=25, max_iters=20, **CURRENT,
    )  # fmt: skip
    assert res.converged is False
    assert any("poorly conditioned" in w for w in res.warnings), res.warnings
    assert res.to_json()["converged"] is False
    # already before fitting: the warning names the pair (and only the pair)
    before = [w for w in res.warnings if w.startswith("before fitting:")]
    assert len(before) == 1 and "A_r" in before[0] and "CL_delta_r" in before[0], res.warnings
    assert "current" not in before[0]


def test_conditioning_before_fit_names_the_weak_combination():
    """J^T J of residuals in which the second parameter acts exactly as the first (a product
    a b: d/d ln a = d/d ln b) and a third acts on its own: singular, the warning names the
    first two with opposite signs and not the third; independent columns: no warning."""
    from vcjax.identify.checks import conditioning_before_fit

    rng = np.random.default_rng(0)
    c1, c3 = rng.normal(size=(2, 50))
    J = np.stack([c1, c1, c3], axis=1)
    w = conditioning_before_fit(["a", "b", "c"], J.T @ J)
    assert w is not None and "poorly conditioned (condition number" in w
    combo = w.split("combination ")[1].split(" of the relative")[0]
    assert combo in ("1 a - 1 b", "1 b - 1 a"), combo  # opposite signs, c not in it
    J_ok = rng.normal(size=(50, 3))
    assert conditioning_before_fit(["a", "b", "c"], J_ok.T @ J_ok) is None
    # nearly, not exactly, dependent: above the limit still warns, with the number
    J_near = np.stack([c1, c1 + 1e-6 * c3, c3], axis=1)
    w = conditioning_before_fit(["a", "b", "c"], J_near.T @ J_near)
    assert w is not None and "> 1e+10" in w


# ------------------------------------------------------------------ standard errors, calibrated


def _noisy(log, seed, scale=1.0):
    sig = scale * np.array(
        [0.02] * 3 + [math.radians(0.1)] * 3 + [0.01] * 3 + [0.002] * 3
        + [math.radians(0.1)] * 2 + [2.0]
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    return dataclasses.replace(log, x=log.x + rng.normal(size=log.x.shape) * sig)


def test_standard_errors_equal_an_independent_dense_sigma2_inverse_jtj():
    """std from the fit (Schur-complement information, delta method) == the square roots of
    the parameter block of sigma^2 (J^T J)^-1, J the dense finite-difference Jacobian of the
    weighted residuals with respect to (z, every segment state), sigma^2 = |r|^2 / (m - n)."""
    names = ["CD_0", "CL_delta_r"]
    log = _noisy(_log(201), seed=3)
    res = fit_logs(
        REMUS, [log], names, step="pvs", initial_scale=1.1, segment_steps=25, max_iters=30,
        **CURRENT,
    )  # fmt: skip
    prob, seg = res.problem, make_segments([log], 25)
    z, s, w = res.z, res.s, res.weights
    p, ns = z.size, s.size

    def r_of(v):
        return prob.residuals(v[:p], v[p:].reshape(s.shape), seg, w).ravel()

    v0 = np.concatenate([z, s.ravel()])
    r0 = r_of(v0)
    J = np.empty((r0.size, p + ns))
    for k in range(p + ns):
        h = 1e-6 * max(1.0, abs(v0[k]))
        e = np.zeros_like(v0)
        e[k] = h
        J[:, k] = (r_of(v0 + e) - r_of(v0 - e)) / (2 * h)
    m = float(seg.mask.sum()) * REMUS.n_x  # real residuals (padding rows are zero)
    sigma2 = float(r0 @ r0) / (m - (p + ns))
    cov = sigma2 * np.linalg.inv(J.T @ J)
    theta = np.array([res.estimates[n] for n in names])  # log scale: d theta / d z = theta
    std_dense = theta * np.sqrt(np.diag(cov)[:p])
    np.testing.assert_allclose([res.std[n] for n in names], std_dense, rtol=2e-3)
    assert all(0 < res.std[n] < abs(res.estimates[n]) for n in names)  # finite, informative


def test_noise_free_fit_recovers_the_truth_and_is_trusted():
    res = fit_logs(
        REMUS, [_log(201)], ["CD_0", "CL_delta_s"], step="pvs", initial_scale=1.3,
        segment_steps=25, max_iters=30, **CURRENT,
    )  # fmt: skip
    for n in ("CD_0", "CL_delta_s"):
        assert res.estimates[n] == pytest.approx(res.nominal[n], rel=1e-7)
    assert res.converged is True and res.warnings == []
    assert set(res.sensitivity) == {"CD_0", "CL_delta_s"}
    assert all(v > 0 for v in res.sensitivity.values())


def test_fit_json_and_figure_carry_the_warnings(tmp_path, capsys):
    """Through the CLI: an untrusted fit (product pair) says converged: false in fit.json and on
    stderr, and exits 0 with its files written."""
    log = _log(201)
    path = save_log_csv(
        tmp_path / "run.csv", log.t, log.x, log.u, REMUS.state_columns, REMUS.command_columns
    )
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{path}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        "current_speed = 0.5\ncurrent_direction_deg = 170.0\n"
        '[fit]\nparams = ["A_r", "CL_delta_r"]\ninitial_scale = 1.2\nsegment_steps = 25\n'
        "max_iters = 20\n"
    )
    out = tmp_path / "out"
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "vcjax: fit: warning: converged: false -- the optimum is not trustworthy" in err
    fit = json.loads((out / "fit.json").read_text())
    assert fit["converged"] is False
    assert any("poorly conditioned" in w for w in fit["warnings"])
    assert set(fit["sensitivity"]) == {"A_r", "CL_delta_r"}
    assert (out / "cost_history.png").stat().st_size > 0


# ------------------------------------------------------------------ issue 31: logs, units, actuators


def _csv_case(tmp_path, edit=None, rows=301, files=None, header=None, bom=False) -> Path:
    """A fit config on the first ``rows`` samples of the reference log after ``edit(cols)``
    (a dict of column arrays), written as a CSV (``header``: its names; ``bom``: with a UTF-8
    byte-order mark); ``files``: the config's list (default: the log once)."""
    log = _log(rows)
    cols = {"t": log.t.copy()}
    cols |= {c: log.x[:, j].copy() for j, c in enumerate(REMUS.state_columns)}
    cols |= {c: log.u[:, j].copy() for j, c in enumerate(REMUS.command_columns)}
    if edit is not None:
        cols = edit(cols) or cols
    path = tmp_path / "log.csv"
    names = list(cols) if header is None else header
    with open(path, "w", encoding="utf-8-sig" if bom else "utf-8") as f:
        f.write("# a test log\n" + ",".join(names) + "\n")
        np.savetxt(f, np.column_stack(list(cols.values())), delimiter=",", fmt="%.12g")
    cfg = tmp_path / "fit.toml"
    listed = json.dumps([str(path)] if files is None else [str(tmp_path / f) for f in files])
    cfg.write_text(
        f'[data]\nfiles = {listed}\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        "current_speed = 0.5\ncurrent_direction_deg = 170.0\n[fit]\n"
        'params = ["CD_0", "CL_delta_r"]\nsegment_steps = 25\n'
    )
    return cfg


def _refused(cfg, tmp_path, capsys) -> str:
    out = tmp_path / "out"
    rc = main(["fit", str(cfg), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("vcjax: fit: ") and err.count("\n") == 1 and "Traceback" not in err
    assert not (out / "fit.json").exists()
    return err


def _deg(*names):
    def edit(cols):
        for n in names:
            cols[n] = np.degrees(cols[n])

    return edit


def test_rudder_and_its_command_both_in_degrees_are_refused(tmp_path, capsys):
    """The issue's case: both in degrees agree with each other (no factor 57 between them), and
    gave converged: true with CL_delta_r 1/28 of the truth; the rudder's 0.50 (deg) is beyond
    its 15 deg = 0.262 rad limit, where the plant saturates it."""
    err = _refused(_csv_case(tmp_path, _deg("delta_r", "delta_r_cmd")), tmp_path, capsys)
    assert "column 'delta_r' reaches 0.5015 at sample 300, beyond the actuator's limit of " in err
    assert "0.2618 rad (15 deg)" in err and "actuator angles must be in rad" in err


def test_an_actuator_within_its_limit_passes_and_just_beyond_is_refused():
    log = _log(101)
    j = REMUS.state_columns.index("delta_s")
    lim = math.radians(15.0)
    for v, ok in ((lim, True), (1.04 * lim, True), (1.06 * lim, False)):
        x = log.x.copy()
        x[50, j] = v
        case = dataclasses.replace(log, x=x)
        if ok:
            check_logs(REMUS, [case])
        else:
            with pytest.raises(ValueError, match="column 'delta_s' reaches 0.2775 at sample 50"):
                check_logs(REMUS, [case])


@pytest.mark.parametrize(
    "est, warned", [(0.0178, True), (0.049, True), (0.051, False), (4.9, False), (5.1, True)]
)
def test_an_actuator_coefficient_far_from_nominal_is_not_trusted(est, warned):
    """The issue's CL_delta_r 0.0178 (nominal 0.5): inside the general factor 100, outside the
    actuator coefficients' factor 10, named with the likely cause."""
    args = (["CL_delta_r"], {"CL_delta_r": est}, {"CL_delta_r": 0.5}, {"CL_delta_r": 1e-4})
    w = trust_warnings(*args, np.eye(1), actuator_coeffs=REMUS.actuator_coeffs)
    assert bool(w) is warned, w
    if warned:
        assert "logged in degrees" in w[0] and f"{est / 0.5:.3g} x its nominal" in w[0]
    assert trust_warnings(*args, np.eye(1)) == []  # without: only the factor 100
    assert REMUS.actuator_coeffs == ("CL_delta_r", "CL_delta_s")


def test_the_same_log_listed_twice_is_refused(tmp_path, capsys):
    cfg = _csv_case(tmp_path, files=["log.csv", "log.csv"])
    err = _refused(cfg, tmp_path, capsys)
    assert "log.csv (entry 2) is listed twice (entry 1)" in err and "sqrt(2)" in err


def test_a_copy_of_a_log_under_another_name_is_refused():
    log = _log(101)
    copy = dataclasses.replace(log, name="copy.csv")
    with pytest.raises(ValueError, match="copy.csv \\(entry 2\\) holds the same data as"):
        check_logs(REMUS, [log, copy])
    check_logs(REMUS, [_log(101), _log(120)])  # two different logs: fine


def test_a_duplicate_column_name_is_refused(tmp_path, capsys):
    names = ["t", *REMUS.state_columns, *REMUS.command_columns]
    names[names.index("v")] = "u"  # two columns named 'u'
    err = _refused(_csv_case(tmp_path, header=names), tmp_path, capsys)
    assert "column 'u' appears twice in the header (line 2, fields 8 and 9)" in err


def test_a_byte_order_mark_is_read(tmp_path):
    """Spreadsheets write a UTF-8 byte-order mark: the first column is 't', not '\\ufefft'
    (the first line holds the provenance, so the mark sits before '#' there; and without one)."""
    _csv_case(tmp_path, bom=True)
    path = tmp_path / "log.csv"
    assert path.read_bytes().startswith(b"\xef\xbb\xbf#")
    log = load_log(path, REMUS.state_columns, REMUS.command_columns)
    np.testing.assert_allclose(log.t, _log(301).t, rtol=1e-11)
    assert log.provenance == "a test log"
    text = path.read_text(encoding="utf-8-sig").split("\n", 1)[1]  # no provenance line
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    np.testing.assert_allclose(
        load_log(path, REMUS.state_columns, REMUS.command_columns).t, log.t, rtol=0
    )


def test_a_byte_order_mark_through_the_cli_reaches_the_checks(tmp_path, capsys):
    """The header read right, the next check speaks (here: time in minutes), not 'missing
    column t'."""
    cfg = _csv_case(tmp_path, lambda c: {**c, "t": c["t"] / 60.0}, bom=True)
    err = _refused(cfg, tmp_path, capsys)
    assert "missing column" not in err and "column 't'" in err


def test_time_in_minutes_is_named_before_the_angles(tmp_path, capsys):
    """A log in minutes turns its heading 60 x too fast per unit of t, which the angle check
    would blame on degrees; time is checked first, against the motion the velocities give."""
    err = _refused(_csv_case(tmp_path, lambda c: {**c, "t": c["t"] / 60.0}), tmp_path, capsys)
    assert "column 't'" in err and "t looks like minutes" in err, err
    assert "degrees" not in err


@pytest.mark.parametrize("factor, ok", [(1.0, True), (2.5, True), (1 / 2.5, True), (3.5, False)])
def test_time_against_motion_bound(factor, ok):
    """The distance the positions cover over the logged speed x time: 1 in seconds; refused
    beyond MAX_MOTION_RATIO (3) either way, named by its factor."""
    log = _log(1500)
    case = dataclasses.replace(log, t=log.t / factor)
    if ok:
        check_logs(REMUS, [case])
    else:
        with pytest.raises(ValueError, match=r"cover 3\.5 x the distance"):
            check_logs(REMUS, [case])


def _zero_log(n=101, dt=0.02):
    t = dt * np.arange(n)
    return _log(n).__class__(
        name="z.csv", t=t, x=np.zeros((n, REMUS.n_x)), u=np.zeros((n, REMUS.n_u))
    )


@pytest.mark.parametrize(
    "column, value, message",
    [
        ("theta", 3.10, None),  # below pi rad: an angle
        ("theta", 3.20, "column 'theta' reaches 3.2 at sample 40: an angle beyond pi rad"),
        ("phi", -3.20, "column 'phi' reaches -3.2 at sample 40"),
        ("delta_r", 3.20, "column 'delta_r' reaches 3.2"),
        ("q", 3.10, None),  # below pi rad/s: a rate
        ("q", 3.20, "column 'q' reaches 3.2 at sample 40: a rate beyond pi rad/s"),
        ("r", -3.20, "rates must be in rad/s"),
        ("p", 3.20, "column 'p' reaches 3.2"),
    ],
)
def test_angle_and_rate_bounds(column, value, message):
    """The magnitude checks at their bounds: pi rad for an angle, pi rad/s for a rate (one
    sample set, the rest of the log zero so that no other check speaks)."""
    log = _zero_log()
    x = log.x.copy()
    x[40, REMUS.state_columns.index(column)] = value
    case = dataclasses.replace(log, x=x)
    if message is None:
        check_logs(REMUS, [case])
    else:
        with pytest.raises(ValueError, match=re.escape(message)):
            check_logs(REMUS, [case])


def test_the_heading_is_judged_by_its_wrapped_rate():
    """A heading is not bounded by pi (it may read 5 rad) and may wrap from +pi to -pi in one
    step; what only degrees explain is a turn faster than pi rad/s between samples."""
    log = _zero_log()
    j = REMUS.state_columns.index("psi")
    x = log.x.copy()
    x[:, j] = 5.0  # a heading of 5 rad: fine
    check_logs(REMUS, [dataclasses.replace(log, x=x)])
    x[:, j] = np.where(np.arange(101) < 50, 3.14, -3.14)  # wraps through pi: 0.003 rad
    check_logs(REMUS, [dataclasses.replace(log, x=x)])
    x[:, j] = 0.0
    x[50:, j] = 0.06  # 0.06 rad in 0.02 s = 3.0 rad/s: below pi rad/s
    check_logs(REMUS, [dataclasses.replace(log, x=x)])
    x[50:, j] = 0.07  # 3.5 rad/s
    with pytest.raises(
        ValueError, match=r"column 'psi' turns by 0\.07 rad in 0\.02 s at sample 49"
    ):
        check_logs(REMUS, [dataclasses.replace(log, x=x)])
