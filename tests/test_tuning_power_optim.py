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
    # a step up at 0.5 on a slope: at s = 1 the loss is 1 higher (more than 1e-6 of 10, the
    # start's loss) while the slope is the start's: no approximate decrease there
    (
        "step-up",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(c=10.0, a=1e-3, m=(1e3, 0.0), step=1.0, at=0.5, width=0.05),
        None,
    ),
]


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
