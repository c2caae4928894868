"""Tests that kill the survivors of a mutation run of the tuner's optimiser: the zoom line search
(``tuning.linesearch``), the guarded tuning loop and its L-BFGS step (``tuning.optim``), the
``vcjax tune`` command (``tuning.command``) and the package's lazy names (``tuning``)
(docs/development/testing.md, "Mutation testing").

The expected values come from elsewhere: optax's own ``scale_by_zoom_linesearch`` run in one
``jax.jit`` (the line search's documented contract: optax's arithmetic step for step, so every
point it evaluates and its final state are optax's), the strong Wolfe conditions checked in
numpy, step sizes worked out by hand on quadratics, Adam's update written out in numpy.
"""

from __future__ import annotations

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from tuning.linesearch import Zoom

# ------------------------------------------------------------------ the zoom line search


def _f(x, p):
    """() a smooth test function of x (2,) with coefficients p (12,): a quadratic bowl around
    ``p[2:4]`` of curvature ``p[1]``, a quartic ``p[4]``, a smoothed kink ``p[5] sqrt(q0^2 +
    p[6]^2)``, a log barrier ``-p[7] log(x0 - p[8])`` (NaN left of ``p[8]``), a smoothed step
    ``p[9] tanh((x0 - p[10]) / p[11])``, offset ``p[0]``."""
    q = x - p[2:4]
    return (
        p[0]
        + 0.5 * p[1] * (q @ q)
        + p[4] * jnp.sum(x**4)
        + p[5] * jnp.sqrt(q[0] ** 2 + p[6] ** 2)
        - p[7] * jnp.log(x[0] - p[8])
        + p[9] * jnp.tanh((x[0] - p[10]) / p[11])
    )


_ZOOM = Zoom()
_vg = jax.jit(jax.value_and_grad(_f))
_init = jax.jit(_ZOOM.init)
_advance = jax.jit(_ZOOM.advance)
_point = jax.jit(_ZOOM.point)
_running = jax.jit(_ZOOM.running)


def _zoom_search(x0, d, p):
    """Zoom driven from the host as the L-BFGS step drives it: the points it evaluates and its
    final state."""
    value, grad = _vg(x0, p)
    s = _init(d, x0, value, grad)
    points = []
    while bool(_running(s)):
        x = _point(s)
        points.append(np.asarray(x))
        s = _advance(s, *_vg(x, p))
    return points, s


_seen: list = []


@jax.jit
def _optax_search(x0, d, p):
    """optax's zoom line search along ``d`` (in its while_loop, one jit); each point it
    evaluates is recorded (``_seen``)."""
    ls = optax.scale_by_zoom_linesearch(max_linesearch_steps=15, initial_guess_strategy="one")

    def fn(x):
        jax.debug.callback(lambda v: _seen.append(np.asarray(v)), x, ordered=True)
        return _f(x, p)

    value, grad = jax.value_and_grad(_f)(x0, p)
    with jax.numpy_dtype_promotion("standard"):
        upd, st = ls.update(d, ls.init(x0), x0, value=value, grad=grad, value_fn=fn)
    return upd, st


def _p(
    c=0.0,
    a=1.0,
    m=(0.0, 0.0),
    quart=0.0,
    kink=0.0,
    eps=1.0,
    bar=0.0,
    wall=-1e3,
    step=0.0,
    at=0.0,
    width=1.0,
):
    return jnp.asarray([c, a, *m, quart, kink, eps, bar, wall, step, at, width], dtype=jnp.float64)


#: (name, x0, d, p, the step sizes evaluated, worked out by hand, or None)
CASES = [
    # step 1 lands on the minimum: slope 0, met at once
    ("exact", [1.0, 1.0], [-1.0, -1.0], _p(), [1.0]),
    # minimum at step 100 along d: doubling until |slope| <= 0.9 |slope0|, s >= 10
    ("doubling", [0.0, 0.0], [1.0, 0.0], _p(m=(100.0, 0.0)), [1.0, 2.0, 4.0, 8.0, 16.0]),
    # minimum at step 0.01: the first step fails sufficient decrease; zoom
    ("zoom", [0.0, 0.0], [1.0, 1.0], _p(m=(0.01, 0.01)), None),
    # a quartic bowl overshot: one parabola step
    ("parabola", [0.1, 0.0], [1.0, 0.0], _p(a=1.0, quart=1.0, m=(3.0, 0.0)), None),
    # a smoothed kink at step 3.5: doubling passes it (s = 4: lower, slope up), the interval
    # [4, 2] is reversed; parabola then cubic steps
    ("reversed", [0.0, 0.0], [1.0, 0.0], _p(a=0.0, kink=1.0, eps=0.01, m=(3.5, 0.0)), None),
    ("kink-far", [0.0, 0.0], [1.0, 0.0], _p(a=0.0, kink=1.0, eps=0.5, m=(5.5, 0.0)), None),
    ("kink-near", [0.0, 0.0], [1.0, 0.0], _p(a=0.0, kink=1.0, eps=1e-3, m=(0.3, 0.0)), None),
    # a barrier: NaN past the wall (x0 <= 0.5) at the first step; bisection back inside
    ("barrier", [1.0, 0.0], [-1.0, 0.0], _p(a=1.0, m=(-3.0, 0.0), bar=1.0, wall=0.5), None),
    # at s = 1 the loss is within 1e-6 of the start's, Armijo's decrease is missed, and the
    # slope is 0.99975 (then 0.99985) of the start's, reversed: just inside (then just outside)
    # Hager and Zhang's approximate decrease, ``slope <= (1 - 2 c1) |slope0|``
    (
        "approx-in",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(
            c=100.0,
            a=2.0,
            m=(1.0, 0.0),
            step=0.5676676416183063,
            at=0.8807672697953313,
            width=0.11923273020466874,
        ),
        None,
    ),
    (
        "approx-out",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(
            c=100.0,
            a=2.0,
            m=(1.0, 0.0),
            step=0.5676676416183063,
            at=0.880779194857111,
            width=0.119220805142889,
        ),
        None,
    ),
    # a slope of 1e-9 under a loss of 1e8: every point rounds to the start's loss (an
    # approximate decrease); the second point, no lower than the first, bounds the interval
    ("flat", [0.0, 0.0], [1.0, 0.0], _p(c=1e8, a=1e-15, m=(1e6, 0.0)), None),
    # an ascent direction: never a decrease, the last point taken
    ("ascent", [0.3, 0.2], [-1.0, -1.0], _p(a=0.1, quart=2.0, m=(5.0, 0.0)), None),
    # NaN at every step tried: the start kept (step 0)
    (
        "nan-wall",
        [0.5 + 1e-6, 0.0],
        [-1.0, 0.0],
        _p(a=1.0, m=(-3.0, 0.0), bar=1e-9, wall=0.5),
        [2.0**-k for k in range(15)],
    ),
    # the minimum out of reach (step 1e6): 15 doublings, failed, the largest safe step
    ("out-of-reach", [0.0, 0.0], [1.0, 0.0], _p(m=(1e6, 0.0)), [2.0**k for k in range(15)]),
    # a kink: the curvature condition holds only in a tiny interval around it
    ("kink", [1.0, 0.0], [-1.0, 0.0], _p(a=0.0, m=(0.3, 0.0), kink=1.0, eps=1e-9), None),
    # a rise at round-off level over a large value: Hager and Zhang's approximate decrease
    ("approx", [0.0, 0.0], [1.0, 0.0], _p(c=1e8, a=1e-9, m=(3.0, 0.0)), None),
    # a step up at 0.5 on a slope: at s = 1 the loss is 1 higher (more than 1e-6 of 509, the
    # start's loss) while the slope is the start's: no approximate decrease there
    (
        "step-up",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(c=10.0, a=1e-3, m=(1e3, 0.0), step=1.0, at=0.5, width=0.05),
        None,
    ),
]


def _assert_optax_search(x0, d, p, points, s):
    """The host-driven search's evaluated ``points`` and final state ``s`` are those of
    ``optax.scale_by_zoom_linesearch`` from ``x0`` along ``d`` on ``p``: every point, the
    count, the step (and optax's update), loss, gradient and both errors."""
    _seen.clear()
    upd, st = _optax_search(x0, d, p)
    jax.effects_barrier()
    ref = [v for v in _seen]  # optax's evaluations (the value_and_grad at the start is not fn's)
    assert len(points) == len(ref) == int(st.info.num_linesearch_steps) == int(s.count)
    np.testing.assert_allclose(np.array(points), np.array(ref), rtol=1e-13, atol=1e-300)
    assert float(s.stepsize) == pytest.approx(float(st.learning_rate), rel=1e-13, abs=1e-300)
    np.testing.assert_allclose(np.asarray(upd), float(s.stepsize) * np.asarray(d), rtol=1e-13)
    assert float(s.value) == pytest.approx(float(st.value), rel=1e-14, abs=1e-300)
    np.testing.assert_allclose(s.grad, st.grad, rtol=1e-13, atol=1e-300)
    for mine, theirs in (
        (s.decrease_error, st.info.decrease_error),
        (s.curvature_error, st.info.curvature_error),
    ):
        assert float(mine) == pytest.approx(float(theirs), rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("name, x0, d, p, hand", CASES, ids=[c[0] for c in CASES])
def test_zoom_evaluates_optax_points_and_meets_strong_wolfe(name, x0, d, p, hand):
    """Every point the host-driven search evaluates, its step size, loss, gradient, count and
    errors are those of ``optax.scale_by_zoom_linesearch`` run in one jit, on searches that
    stop at once, double, zoom by bisection, parabola and cubic, meet NaN, run out of
    evaluations and take the safe step, stall in a tiny interval, or accept Hager and Zhang's
    approximate decrease; where the search succeeds its step meets both strong Wolfe
    conditions (c1 = 1e-4, c2 = 0.9: numpy), and the hand-worked step sizes are tried."""
    x0, d = jnp.asarray(x0), jnp.asarray(d)
    points, s = _zoom_search(x0, d, p)
    _assert_optax_search(x0, d, p, points, s)
    if hand is not None:
        steps = [
            float((pt - np.asarray(x0)) @ np.asarray(d) / (np.asarray(d) @ np.asarray(d)))
            for pt in points
        ]
        np.testing.assert_allclose(steps, hand, rtol=1e-15)
    # strong Wolfe, in numpy, at the step taken when the search met both conditions
    f0, g0 = (np.asarray(v) for v in _vg(x0, p))
    eta, f1, g1 = float(s.stepsize), float(s.value), np.asarray(s.grad)
    slope0, slope1 = float(g0 @ np.asarray(d)), float(g1 @ np.asarray(d))
    assert bool(s.done) != bool(s.failed)
    if bool(s.done):
        assert f1 <= f0 + 1e-4 * eta * slope0 and abs(slope1) <= 0.9 * abs(slope0)
    if name == "out-of-reach":  # failed: the largest step with sufficient decrease
        assert eta == 2.0**14 and f1 == pytest.approx(0.5 * (1e6 - 2.0**14) ** 2, rel=1e-15)
    if name == "nan-wall":  # failed outside the domain: the start
        assert eta == 0.0 and f1 == f0
    if name == "ascent":  # failed, nothing safe: the last point
        assert eta == 2.0**-14 and np.isfinite(f1) and f1 > f0


def test_zoom_settings_are_optax_defaults_static_and_hashable():
    """Kills: ``Zoom`` no longer frozen (unhashable: it could not key a compiled program), a
    default off optax's (``scale_by_zoom_linesearch``'s signature; ``interval_threshold`` is
    its ``stepsize_precision``; 15 evaluations, ``optax.lbfgs``'s)."""
    import inspect

    assert hash(Zoom()) == hash(Zoom(max_linesearch_steps=15)) and Zoom() == Zoom()
    with pytest.raises(AttributeError):
        Zoom().tol = 1.0  # frozen
    ref = inspect.signature(optax.scale_by_zoom_linesearch).parameters
    z = Zoom()
    for mine, theirs in [
        ("tol", "tol"),
        ("increase_factor", "increase_factor"),
        ("slope_rtol", "slope_rtol"),
        ("curv_rtol", "curv_rtol"),
        ("approx_dec_rtol", "approx_dec_rtol"),
        ("interval_threshold", "stepsize_precision"),
    ]:
        assert getattr(z, mine) == ref[theirs].default, mine
    assert z.max_linesearch_steps == 15


# ------------------------------------------------------------------ vcjax tune, the command


def _stub_tuner(monkeypatch, summary=None, error=None):
    """``vcjax tune`` with its tuner replaced (``run_tune_config``, found through ``tuning``'s
    lazy names): it returns ``summary`` (or raises ``error``) and one written file."""
    import tuning.run

    calls = []

    def fake(config, out, cfg=None):
        calls.append(config)
        if error is not None:
            raise error
        return {"files": [f"{out}/gains.json"], "summary": summary}

    monkeypatch.setattr(tuning.run, "run_tune_config", fake)
    # a test that patched the lazy name ``tuning.run_tune_config`` itself leaves the real
    # function bound in ``tuning`` (pytest's undo sets what ``__getattr__`` returned): drop it
    # for this test, so that ``vcjax tune`` looks the name up in ``tuning.run`` again
    monkeypatch.delitem(vars(tuning), "run_tune_config", raising=False)
    return calls


def _tune(tmp_path, capsys, text=""):
    from vcjax import cli

    cfg = tmp_path / "t.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    rc = cli.main(["tune", str(cfg), "--out", str(out)])
    o = capsys.readouterr()
    return rc, o.out, o.err, out


def test_tune_command_reports_an_interrupted_run_with_its_exit_code(tmp_path, capsys, monkeypatch):
    """Kills (``tuning.command``): an interrupted run reported as a success (exit 0 instead of
    130) or without the steps done; the held-out line's numbers and wording; run.json left
    unwritten. The tuner is a stand-in: the command's own logic only."""
    summary = {
        "heldout_loss_before": 2.0,
        "heldout_loss_after": 1.5,
        "interrupted": True,
        "iterations": 2,
        "steps_planned": 40,
    }
    calls = _stub_tuner(monkeypatch, summary)
    rc, out, err, folder = _tune(tmp_path, capsys)
    assert rc == 130 and len(calls) == 1
    assert "held-out loss: 2 -> 1.5 (25.0 % lower)" in out
    assert f"wrote {folder}/gains.json" in out
    assert "tune: interrupted" in err and "after 2 of 40 steps" in err
    assert json.loads((folder / "run.json").read_text())["command"] == "tune"


@pytest.mark.parametrize(
    "summary, rc, line",
    [
        ({"aborted": True, "reason": "aborted: 5 consecutive non-finite steps"}, 2, "aborted"),
        ({"heldout_loss_before": 2.0, "heldout_loss_after": None}, 0, None),
        ({"heldout_loss_before": None, "heldout_loss_after": 1.0}, 0, None),
        (None, 0, None),  # a process other than 0 of a multi-process run
    ],
    ids=["aborted", "no-after", "no-before", "not-process-0"],
)
def test_tune_command_exit_status_and_heldout_line(
    tmp_path, capsys, monkeypatch, summary, rc, line
):
    """Kills: an aborted run's exit status (2, ``tune: aborted: REASON``), the held-out line
    printed when either loss is missing, process > 0's summary (None) read."""
    _stub_tuner(monkeypatch, summary)
    got, out, err, _ = _tune(tmp_path, capsys)
    assert got == rc and "held-out loss" not in out
    if line is not None:
        assert "tune: aborted: aborted: 5 consecutive non-finite steps" in err
    else:
        assert err == ""


def test_tune_command_refuses_before_touching_out(tmp_path, capsys, monkeypatch):
    """Kills: a bad ``problem.initial_gains`` file not checked before ``--out`` is made (or
    checked when none is named); an error of the tuner not turned into exit 2 and one line."""
    calls = _stub_tuner(monkeypatch, {"heldout_loss_before": 1.0, "heldout_loss_after": 1.0})
    bad = tmp_path / "gains.json"
    bad.write_text("{not json")
    rc, out, err, folder = _tune(tmp_path, capsys, f'[problem]\ninitial_gains = "{bad}"\n')
    assert rc == 2 and "problem.initial_gains" in err and not folder.exists() and not calls
    _stub_tuner(monkeypatch, error=ValueError("the batch is empty"))
    rc, out, err, folder = _tune(tmp_path, capsys)
    assert rc == 2 and err.strip() == "vcjax: tune: the batch is empty"


def test_tune_runs_across_processes_under_launch(capsys):
    """Kills: ``vcjax tune`` no longer declared distributed (``vcjax launch`` would refuse it):
    launch accepts it and asks for ``-n`` next; it refuses ``simulate``."""
    from vcjax import cli

    assert cli.main(["launch", "--", "simulate", "sim1"]) == 2
    assert "one of ['sweep', 'tune']" in capsys.readouterr().err
    assert cli.main(["launch", "--", "tune", "x.toml"]) == 2
    assert "-n N" in capsys.readouterr().err


# ------------------------------------------------------------------ tuning's lazy names


def test_importing_tuning_imports_none_of_its_modules():
    """Kills (``tuning/__init__.py``): the names imported at ``import tuning`` (the CLI imports
    it for every ``vcjax`` call, before the precision is chosen), or not found on first use."""
    import subprocess
    import sys

    code = (
        "import sys, tuning; print(sorted(m for m in sys.modules if m.startswith(('tuning', "
        "'jax', 'vcjax'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['tuning']"
    import tuning
    import tuning.params

    assert tuning.GainSpace is tuning.params.GainSpace
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        tuning.nothing  # noqa: B018


# ------------------------------------------------------------------ the guarded tuning loop


def _adam_numpy(grad_fn, theta, steps, lr, b1=0.9, b2=0.999, eps=1e-8):
    """Adam's iterates written out (Kingma and Ba, algorithm 1; optax's defaults)."""
    theta = np.array(theta, dtype=float)
    m = np.zeros_like(theta)
    v = np.zeros_like(theta)
    out = []
    for t in range(1, steps + 1):
        g = grad_fn(theta)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        upd = -lr * (m / (1 - b1**t)) / (np.sqrt(v / (1 - b2**t)) + eps)
        out.append((theta.copy(), g, upd))
        theta = theta + upd
    return out, theta


def _bowl(th, c):
    """() a quadratic bowl around ``c`` (2,)."""
    return 0.5 * jnp.sum((th - c) ** 2)


def test_adam_steps_follow_the_formula_and_the_history_reports_them():
    """Kills (``tuning.optim``): Adam's default learning rate, the update's scale, the step's
    gradient norm, update norm, loss and evaluation counts in the history, the best iterate
    (the final one, evaluated after the loop, when lower). Adam in numpy."""
    from tuning.optim import make_optimizer, run_gradient_tuner

    c = np.array([1.0, -2.0])
    assert make_optimizer("adam") is not None
    seen = []
    res = run_gradient_tuner(
        _bowl,
        jnp.asarray([0.0, 0.0]),
        (jnp.asarray(c),),
        optimizer="adam",
        steps=3,
        on_step=lambda k, th, rec: seen.append(np.asarray(th)) or {"mine": k},
    )
    ref, final = _adam_numpy(lambda th: th - c, [0.0, 0.0], 3, lr=0.05)  # the default rate
    for k, (rec, (th, g, upd)) in enumerate(zip(res.history, ref, strict=True)):
        assert rec["iter"] == k and rec["ok"] and rec["evals"] == 1 and rec["mine"] == k
        assert rec["cum_evals"] == k + 1
        assert rec["loss"] == pytest.approx(0.5 * np.sum((th - c) ** 2), rel=1e-12)
        assert rec["grad_norm"] == pytest.approx(np.linalg.norm(g), rel=1e-12)
        assert rec["update_norm"] == pytest.approx(np.linalg.norm(upd), rel=1e-9)
        np.testing.assert_allclose(seen[k], th + upd, rtol=1e-9)
    np.testing.assert_allclose(res.theta, final, rtol=1e-9)  # the final iterate, lower
    assert res.loss == pytest.approx(0.5 * np.sum((final - c) ** 2), rel=1e-9)
    assert res.evals == 3 and res.n_bad == 0 and res.reason == "steps" and not res.aborted


def _walled(th, c):
    """The bowl, NaN (and a NaN gradient) right of ``th[0] = c[2]``."""
    bad = th[0] > c[2]
    past = jnp.where(bad, th, 0.0)  # (double where: a NaN gradient only past the wall)
    return jnp.where(bad, jnp.nan * past[0], _bowl(th, c[:2]))


def test_the_guard_reverts_halves_the_step_and_reports_each_rejection():
    """Kills: the guard's revert (to the last accepted step's input and its optimiser state),
    its halving of the step (0.5), the rejected step's record (loss and gradient norm None,
    update norm 0, not ok), the rejection count, the consecutive count reset by an accepted
    step. Adam with the guard in numpy: the wall at 0.45 is crossed by the second step."""
    from tuning.optim import run_gradient_tuner

    c = np.array([1.0, 1.0, 0.45])
    res = run_gradient_tuner(
        _walled, jnp.zeros(2), (jnp.asarray(c),), optimizer="adam", steps=4, learning_rate=0.3
    )
    # numpy: step 0 from 0 (accepted, to 0.3); step 1 from 0.3 (accepted: its loss is finite;
    # its update lands at 0.593, past the wall); step 2 there: NaN, rejected: back to step 1's
    # input 0.3 with step 1's state, scale 1/2: step 3 from 0.3 lands at 0.446 (inside)
    b1, b2, lr = 0.9, 0.999, 0.3
    g0 = np.array([-1.0, -1.0])
    m0, v0 = (1 - b1) * g0, (1 - b2) * g0 * g0
    u0 = -lr * (m0 / (1 - b1)) / (np.sqrt(v0 / (1 - b2)) + 1e-8)
    th1 = u0
    g1 = th1 - 1.0
    m1, v1 = b1 * m0 + (1 - b1) * g1, b2 * v0 + (1 - b2) * g1 * g1
    u1 = -lr * (m1 / (1 - b1**2)) / (np.sqrt(v1 / (1 - b2**2)) + 1e-8)
    th3 = th1 + 0.5 * u1
    h = res.history
    assert [r["ok"] for r in h] == [True, True, False, True]
    assert h[2]["loss"] is None and h[2]["grad_norm"] is None and h[2]["update_norm"] == 0.0
    assert h[3]["loss"] == pytest.approx(0.5 * np.sum((th1 - 1.0) ** 2), rel=1e-12)
    assert h[3]["update_norm"] == pytest.approx(np.linalg.norm(0.5 * u1), rel=1e-9)
    assert res.n_bad == 1 and not res.aborted and res.reason == "steps"
    assert np.all(th1 + u1 > 0.45) and np.all(th3 < 0.45)  # (the numbers above)
    np.testing.assert_allclose(res.theta, th3, rtol=1e-9)  # the final iterate, the lowest


@pytest.mark.parametrize(
    "options, reason, n",
    [
        ({"grad_tol": 0.0}, "stalled", 3),  # zero gradient: zero updates, three in a row
        ({"grad_tol": 5.0}, "converged", 2),  # |g| = 5 at the start is not below 5
        ({"grad_tol": 5.000001}, "converged", 1),
        ({"max_bad_steps": 2, "c": [0.0, 0.0, -1.0]}, "aborted: 2 consecutive non-finite steps", 2),
    ],
)
def test_why_the_loop_stops(options, reason, n):
    """Kills: the stall count (3 zero updates in a row) and its reset, the convergence test
    (strictly below ``grad_tol``), the abort after exactly ``max_bad_steps`` rejections."""
    from tuning.optim import run_gradient_tuner

    opts = dict(options)
    c = opts.pop("c", None)
    if "grad_tol" in opts and opts["grad_tol"] == 0.0:
        th0, c = jnp.asarray([1.0, -2.0]), [1.0, -2.0, 9.0]  # at the minimum: g = 0
    elif c is None:
        th0, c = jnp.asarray([3.0, 4.0]), [0.0, 0.0, 9.0]  # g = (3, 4)
    else:
        th0 = jnp.zeros(2)  # past the wall: NaN from the start
    res = run_gradient_tuner(
        _walled, th0, (jnp.asarray(c),), optimizer="adam", steps=4, learning_rate=0.3, **opts
    )
    assert res.reason == reason and len(res.history) == n
    assert res.aborted == reason.startswith("aborted")
    if res.aborted:  # never a result from a NaN loss: the start
        np.testing.assert_array_equal(res.theta, th0)


def test_an_interrupted_loop_returns_the_best_input_and_evaluates_nothing_more():
    """Kills: ``should_stop`` not polled, or the final iterate evaluated after a stop (the
    best gains are then those of the step's input, the start here, not the new iterate)."""
    from tuning.optim import run_gradient_tuner

    evaluated = []

    def loss(th, c):
        jax.debug.callback(lambda: evaluated.append(1))
        return _bowl(th, c)

    res = run_gradient_tuner(
        loss, jnp.zeros(2), (jnp.ones(2),), optimizer="adam", steps=5, should_stop=lambda: True
    )
    jax.effects_barrier()
    assert res.reason == "interrupted" and len(res.history) == 1 and len(evaluated) == 1
    np.testing.assert_array_equal(res.theta, [0.0, 0.0])
    assert res.loss == 1.0


def test_tuner_settings_are_checked_and_default_to_the_configs():
    """Kills: ``steps`` / ``max_bad_steps`` taken when not a positive int (a float, 0), one
    step refused; the optimiser's defaults off the ``[optimizer]`` section's documented ones
    (``tuning.spec``); an unknown optimiser or gradient mode, or an Adam optimiser given to
    an L-BFGS step, accepted."""
    from tuning.optim import LBFGS, TunerOptions, make_optimizer, make_step, run_gradient_tuner
    from tuning.spec import Optimizer

    loss = lambda th: jnp.sum(th**2)
    for bad in ({"steps": 2.0}, {"steps": 0}, {"max_bad_steps": 1.5}, {"max_bad_steps": 0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            run_gradient_tuner(loss, jnp.ones(1), optimizer="adam", **bad)
    one = run_gradient_tuner(loss, jnp.ones(1), optimizer="adam", steps=1, max_bad_steps=1)
    assert len(one.history) == 1
    spec, opts = Optimizer(), TunerOptions()
    for k in ("learning_rate", "memory_size", "max_linesearch_steps", "grad_mode"):
        assert getattr(opts, k) == getattr(spec, k), k
    assert (opts.optimizer, opts.max_bad_steps, opts.grad_tol) == (
        spec.name,
        spec.max_bad_steps,
        spec.grad_tol,
    )
    lb = make_optimizer()
    assert isinstance(lb, LBFGS) and (lb.memory_size, lb.max_linesearch_steps) == (10, 15)
    section = {**dataclasses.asdict(spec), "learning_rate": 0.2}
    got = TunerOptions.from_section(section, steps=7)
    assert got.optimizer == "lbfgs" and got.learning_rate == 0.2 and got.steps == 7
    with pytest.raises(ValueError, match="sgd"):
        make_optimizer("sgd")
    with pytest.raises(ValueError, match="sgd"):
        make_step(loss, lb, "sgd")
    with pytest.raises(ValueError, match="sideways"):
        make_step(loss, lb, "lbfgs", "sideways")
    with pytest.raises(ValueError, match="L-BFGS"):
        make_step(loss, make_optimizer("adam"), "lbfgs")


def _cubed(th):
    """``x`` after three rounds of ``x <- x a + b`` from 1 (a ``while_loop``: forward mode
    only), ``th = (a, b)``."""
    _, x = jax.lax.while_loop(
        lambda c: c[0] < 3, lambda c: (c[0] + 1, c[1] * th[0] + th[1]), (0, jnp.ones((), th.dtype))
    )
    return x


@pytest.mark.parametrize("optimizer", ["adam", "lbfgs"])
def test_forward_mode_steps_differentiate_what_reverse_mode_cannot(optimizer):
    """Kills: ``grad_mode="forward"`` not used (reverse mode cannot differentiate a
    ``while_loop``), its gradient: ``a^3 + a^2 b + a b + b`` by hand."""
    from tuning.optim import init_state, make_optimizer, make_step

    opt = make_optimizer(optimizer)
    th = jnp.asarray([0.5, 2.0])
    a, b = 0.5, 2.0
    g = np.array([3 * a**2 + 2 * a * b + b, a**2 + a + 1])
    step = make_step(lambda t: _cubed(t), opt, optimizer, "forward")
    _, _, info = step(th, init_state(opt, th), jnp.asarray(1.0), ())
    assert float(info.loss) == pytest.approx(a**3 + a**2 * b + a * b + b, rel=1e-14)
    assert float(info.grad_norm) == pytest.approx(np.linalg.norm(g), rel=1e-14)
    with pytest.raises(ValueError, match="[Rr]everse-mode"):
        rev = make_step(lambda t: _cubed(t), opt, optimizer, "reverse")
        rev(th, init_state(opt, th), jnp.asarray(1.0), ())


def test_forward_mode_gives_arguments_zero_cotangents():
    """Kills: ``forward_mode``'s zero cotangents of the other arguments (floats: zeros;
    integers: float0), the cotangent's scaling of the gradient."""
    from tuning.optim import forward_mode

    f = lambda th, a, n: jnp.sum(th**2 * a) * n
    g = forward_mode(f)
    th, a, n = jnp.asarray([1.0, 2.0]), jnp.asarray([3.0, 4.0]), jnp.asarray(2)
    v, vjp = jax.vjp(g, th, a, n)
    d_th, d_a, d_n = vjp(jnp.asarray(0.5))
    np.testing.assert_allclose(d_th, 0.5 * 2 * np.array([1.0, 2.0]) * np.array([3.0, 4.0]) * 2)
    np.testing.assert_array_equal(d_a, [0.0, 0.0])
    assert d_n.dtype == jax.dtypes.float0
    assert float(v) == 38.0
