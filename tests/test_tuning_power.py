"""Tests that kill the planted bugs the tuner's own tests let through (issue 31, item 8): its
scenario sampling (units: degrees vs radians, knots vs m/s; the held-out batch independent of
the training batch), its loss terms, and its interrupted-run summary; then the survivors of a
mutation run of ``tuning/`` (docs/development/testing.md, "Mutation testing"): the scenario
distribution's defaults and checks, the loss's arguments, robust tuning's bookkeeping (its
searches replaced by stand-ins), the gain space's floors, the config's documented defaults and
bounds, the Bayesian baseline's arguments. Each test names the bugs it kills; the expected
values are computed here independently (numpy, written-out formulas), not with the code under
test.
"""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tuning import run as tcli
from tuning.config import load_config
from tuning.loss import (
    TERMS,
    LossWeights,
    TuningProblem,
    aggregate,
    box_penalty,
    loss_weights,
    problem_data,
    rollout_terms,
    scenario_losses,
    weighted_loss,
)
from tuning.params import FRAC_MAX, GainSpace, default_loop, rh_bound
from tuning.robust import RobustSearch, TuningLossMetric, concat_batches, report
from tuning.scenarios import (
    SCENARIO_AXES,
    Nominal,
    batch_size,
    sample_scenarios,
    scenario_spec,
    shard_scenarios,
)
from vcjax import loops
from vcjax.loops import Signals

N_SAMPLE = 512

# ------------------------------------------------------------------ scenario sampling: units


@pytest.fixture(scope="module")
def batch():
    return sample_scenarios(
        3, N_SAMPLE, current_max=1.0, position_offset=5.0, heading_offset=math.pi / 4
    )


def test_heading_offsets_are_radians_over_the_whole_range(batch):
    """Kills: the heading offset used as degrees (h = heading_offset instead of its conversion:
    +-0.785 deg instead of +-45 deg) or converted twice. Simulation 1 starts at psi = pi/2."""
    psi = np.asarray(batch.eta0[:, 2])
    lo, hi = math.pi / 2 - math.pi / 4, math.pi / 2 + math.pi / 4
    assert np.all(psi >= lo - 1e-12) and np.all(psi <= hi + 1e-12)
    # 512 uniform draws: the extremes within 1 % of the range of the bounds (P(fail) ~ e^-5)
    assert psi.min() < lo + 0.01 * (hi - lo) and psi.max() > hi - 0.01 * (hi - lo)
    assert np.std(psi) == pytest.approx((hi - lo) / math.sqrt(12.0), rel=0.1)


def test_position_offsets_are_metres_over_the_whole_range(batch):
    for j in (0, 1):
        x = np.asarray(batch.eta0[:, j])
        assert np.all(np.abs(x) <= 5.0 + 1e-12)
        assert x.min() < -4.9 and x.max() > 4.9


def test_currents_are_metres_per_second_in_every_direction(batch):
    """Kills: the current's direction range (0, 360) used in radians or degrees twice (all
    currents within 6 deg of north), a speed in knots (x 0.514 or / 0.514), the components
    swapped or the sign of one flipped (the direction distribution stays uniform, so those are
    caught by the octants only together with the speed law)."""
    c = np.asarray(batch.current)
    assert c.shape == (N_SAMPLE, 3) and np.all(c[:, 2] == 0.0)
    speed = np.hypot(c[:, 0], c[:, 1])
    assert np.all(speed <= 1.0 + 1e-12) and speed.max() > 0.99
    assert np.mean(speed) == pytest.approx(0.5, abs=0.04)  # U(0, 1): mean 1/2
    direction = np.arctan2(c[:, 1], c[:, 0]) % (2 * math.pi)
    counts = np.bincount((direction // (math.pi / 4)).astype(int), minlength=8)
    assert np.all(counts > N_SAMPLE / 8 * 0.6), counts  # every octant, ~64 each


def test_the_sampled_direction_and_speed_are_those_of_the_sweep_api():
    """The direction the current flows towards, from north towards east (NED): a range of
    [90, 90] deg is a current towards east, at the given speed."""
    b = sample_scenarios(
        0,
        4,
        extra={"current_speed": (0.7, 0.7), "current_direction_deg": (90.0, 90.0)},
    )
    np.testing.assert_allclose(np.asarray(b.current)[:, :2], [[0.0, 0.7]] * 4, atol=1e-12)


# ------------------------------------------------------------------ the held-out batch

TUNE = """
[problem]
variant = "vcm_integral"
horizon = 1.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 4
seed = {train}
[heldout]
size = {heldout_size}
seed = {heldout}
[optimizer]
name = "adam"
steps = {steps}
[report]
plot_scenarios = 1
"""


def _tune_cfg(tmp_path, train=0, heldout=1001, heldout_size=4, steps=3, name="t.toml"):
    p = tmp_path / name
    p.write_text(TUNE.format(train=train, heldout=heldout, heldout_size=heldout_size, steps=steps))
    return p


def test_the_heldout_batch_is_drawn_from_its_own_seed(tmp_path):
    """Kills: the held-out batch drawn with the training seed (it would then be the training
    batch: no test of generalisation), or with the training size."""
    _, _, _, train, heldout = tcli.build(load_config(_tune_cfg(tmp_path, heldout_size=6)))
    assert heldout.eta0.shape[0] == 6 and train.eta0.shape[0] == 4
    # no held-out scenario is a training scenario (start and current)
    tr = np.concatenate([np.asarray(train.eta0), np.asarray(train.current)], axis=1)
    ho = np.concatenate([np.asarray(heldout.eta0), np.asarray(heldout.current)], axis=1)
    assert np.min(np.abs(ho[:, None, :] - tr[None, :, :]).sum(-1)) > 1e-3
    # it is the batch of its own seed: the same as a training batch drawn with that seed
    other = _tune_cfg(tmp_path, train=1001, heldout=1002, name="b.toml")
    _, _, _, train_1001, _ = tcli.build(load_config(other))
    np.testing.assert_array_equal(np.asarray(heldout.eta0)[:4], np.asarray(train_1001.eta0))
    np.testing.assert_array_equal(np.asarray(heldout.current)[:4], np.asarray(train_1001.current))


# ------------------------------------------------------------------ loss terms by hand

#         step:      0      1      2      3
S = np.array([1.0, -2.0, 0.5, 0.0])
E = np.array([0.0, 1.0, -1.0, 2.0])
U_ERR = np.array([0.1, -0.2, 0.0, 0.3])
PSI = np.array([0.5, 0.0, -0.5, 0.0])
DEPTH = np.array([0.0, 1.0, 0.0, -1.0])
CMD = np.array([[0.5, 0.0], [1.5, -1.0], [-2.0, 0.2], [1.0, 0.0]])  # commands / limits
FINITE = np.array([True, True, False, True])
W = 0.1  # sat_width


def _signals():
    z = jnp.zeros((4, 3))
    return Signals(
        eps=jnp.stack([jnp.asarray(S), jnp.asarray(E)], axis=1),
        pos=z,
        p_err=z,
        u_err=jnp.asarray(U_ERR),
        psi_err=jnp.asarray(PSI),
        depth_err=jnp.asarray(DEPTH),
        cmd_ratio=jnp.asarray(CMD),
        sat=jnp.asarray(np.any(np.abs(CMD) >= 1, axis=1)),
        act={},
    )


class _Traj:
    finite = jnp.asarray(FINITE)


def test_each_loss_term_by_hand():
    """Kills: a term's square or mean dropped, the excess measured from 0 instead of the limit,
    the smooth count's width squared wrongly, the health fraction inverted.

    Worked by hand (means over the 4 steps):
    eps = (1 + 5 + 1.25 + 4) / 4 = 2.8125; u = (0.01 + 0.04 + 0 + 0.09) / 4 = 0.035;
    psi = (0.25 + 0 + 0.25 + 0) / 4 = 0.125; depth = (0 + 1 + 0 + 1) / 4 = 0.5;
    excess over the limit: step 1: 0.5 (and |-1| - 1 = 0), step 2: 1.0; so
    sat_excess = (0.25 + 1) / 4 = 0.3125; sat_time = (0.25/(0.25+0.01) + 1/(1+0.01)) / 4;
    effort = (0.25 + 3.25 + 4.04 + 1) / 4 = 2.135; unhealthy = 1/4.
    """
    t = {k: float(v) for k, v in rollout_terms(_Traj(), _signals(), W).items()}
    assert sorted(t) == sorted(TERMS)
    want = {
        "eps": 2.8125,
        "u_tilde": 0.035,
        "psi_tilde": 0.125,
        "depth": 0.5,
        "sat_excess": 0.3125,
        "sat_time": (0.25 / 0.26 + 1.0 / 1.01) / 4.0,
        "effort": 2.135,
        "unhealthy": 0.25,
    }
    for k, v in want.items():
        assert t[k] == pytest.approx(v, rel=1e-12, abs=1e-15), k


def test_the_smooth_time_over_limit_tends_to_the_count():
    """x^2 / (x^2 + w^2): 0 inside the limits, 1/2 at x = w, -> 1 far beyond."""
    for ratio, want in ((0.9, 0.0), (1.0 + W, 0.5), (1.0 + 100 * W, 1e4 / (1e4 + 1))):
        sig = _signals()._replace(cmd_ratio=jnp.full((4, 1), ratio))
        got = float(rollout_terms(_Traj(), sig, W)["sat_time"])
        assert got == pytest.approx(want, rel=1e-12, abs=1e-15)


def test_aggregate_mean_and_cvar_and_the_box():
    """CVaR at alpha: the mean of the ceil(alpha B) worst; the box: a quadratic outside +-log_box
    of the reference only."""
    losses = jnp.asarray([1.0, 5.0, 2.0, 8.0, 3.0])
    space = GainSpace()
    mean = TuningProblem(space=space, num_steps=5)
    assert float(aggregate(losses, mean)) == pytest.approx(3.8)
    cvar = TuningProblem(space=space, num_steps=5, risk="cvar", alpha=0.4)
    assert float(aggregate(losses, cvar)) == pytest.approx(6.5)  # (8 + 5) / 2
    assert (
        float(aggregate(losses, TuningProblem(space=space, num_steps=5, risk="cvar", alpha=0.2)))
        == 8.0
    )
    data = problem_data(mean, log_box=1.0, box_weight=10.0)
    ref = np.asarray(data.theta_ref)
    assert float(box_penalty(jnp.asarray(ref + 0.9), data)) == 0.0
    d = np.zeros_like(ref)
    d[0], d[-1] = 1.5, -3.0  # 0.5 and 2.0 beyond the box
    assert float(box_penalty(jnp.asarray(ref + d), data)) == pytest.approx(10.0 * (0.25 + 4.0))


def test_the_weighted_loss_counts_every_term_with_its_own_weight():
    """Kills: a term missing from the sum (the depth term too, which a planar loop's rollout
    leaves at 0) or weighted by another term's weight: every term and weight distinct (primes),
    so each product is seen in the sum."""
    weights = loss_weights(eps=2.0, u_tilde=3.0, psi_tilde=5.0, sat_excess=7.0, sat_time=11.0,
                           effort=13.0, unhealthy=17.0, depth=19.0)  # fmt: skip
    values = dict(zip(TERMS, (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8), strict=True))
    terms = {k: jnp.asarray(v) for k, v in values.items()}
    want = sum(float(getattr(weights, k)) * v for k, v in values.items())
    assert float(weighted_loss(terms, weights)) == pytest.approx(want, rel=1e-14)
    for k in TERMS:  # each term moves the loss by its own weight
        bumped = dict(terms, **{k: terms[k] + 1.0})
        step = float(weighted_loss(bumped, weights)) - float(weighted_loss(terms, weights))
        assert step == pytest.approx(float(getattr(weights, k)), rel=1e-12), k


def test_the_scenario_loss_is_the_weighted_sum_of_its_terms():
    """Kills: a term missing from the sum or weighted by another term's weight (every weight
    distinct here, each term checked against the sum)."""
    space = GainSpace()
    problem = TuningProblem(space=space, num_steps=6, integrator="euler")
    weights = loss_weights(eps=1.1, u_tilde=2.3, psi_tilde=3.7, sat_excess=5.9, sat_time=7.1,
                           effort=11.3, unhealthy=13.7, depth=17.9)  # fmt: skip
    data = problem_data(problem, weights=weights)
    sc = sample_scenarios(0, 2, current_max=1.5)
    losses, terms = scenario_losses(data.theta_ref, data, sc, problem)
    want = sum(float(getattr(weights, k)) * np.asarray(terms[k]) for k in TERMS)
    np.testing.assert_allclose(np.asarray(losses), want, rtol=1e-12)
    assert all(np.all(np.asarray(terms[k]) >= 0) for k in TERMS)
    assert np.all(np.asarray(terms["eps"]) > 0)  # the offsets make path errors


# ------------------------------------------------------------------ the interrupted run


def test_an_interrupted_tune_says_so_in_its_summary(tmp_path, monkeypatch):
    """Kills: the interrupted flag or the planned steps left out of (or wrong in) summary.json,
    the before/after figures drawn after a stop (new compiles once the user asked to stop).
    The stop is requested after the second step, in-process (no signal, no subprocess)."""
    calls = {"n": 0}

    def stop_after_two():
        calls["n"] += 1
        return calls["n"] >= 2

    monkeypatch.setattr(tcli, "stop_requested_everywhere", stop_after_two)
    cfg = _tune_cfg(tmp_path, steps=1000)
    out = tmp_path / "out"
    res = tcli.run_tune_config(cfg, out, progress=None)
    s = json.loads((out / "summary.json").read_text())
    assert s == json.loads(json.dumps(res["summary"]))
    assert s["interrupted"] is True and s["reason"] == "interrupted"
    assert s["steps_planned"] == 1000 and s["iterations"] == 2
    hist = json.loads((out / "history.json").read_text())
    assert hist["reason"] == "interrupted" and len(hist["iterations"]) == 2
    assert not list(out.glob("before_after*"))  # no figures that need new compiles
    assert math.isfinite(s["heldout_loss_after"])
    jax.clear_caches()


# ------------------------------------------------------------------ the distribution's contract


def test_scenario_spec_defaults_keywords_and_refusals():
    """Kills: a default of ``scenario_spec`` changed (current speed U(0, 1) m/s in any
    direction, +-5 m, +-pi/4 rad = +-45 deg about Simulation 1's start x = y = 0, 90 deg), its
    distribution arguments made positional, the check of the three bounds skipped."""
    loop = default_loop()
    s = scenario_spec(loop)
    assert dict(s.initial.values) == {
        "x": (-5.0, 5.0),
        "y": (-5.0, 5.0),
        "heading_deg": pytest.approx((45.0, 135.0), rel=1e-15),
    }
    assert s.current.speed == (0.0, 1.0) and s.current.direction_deg == (0.0, 360.0)
    with pytest.raises(TypeError):
        scenario_spec(loop, 1.0)  # keyword-only
    zero = scenario_spec(loop, current_max=0.0, position_offset=0.0, heading_offset=0.0)
    assert dict(zero.initial.values) == {"x": (0, 0), "y": (0, 0), "heading_deg": (90, 90)}
    for name in ("current_max", "position_offset", "heading_offset"):
        for bad in (-0.1, math.inf, math.nan):
            with pytest.raises(ValueError, match=rf"^{name}: expected a finite value >= 0"):
                scenario_spec(loop, **{name: bad})


def test_only_the_horizontal_start_and_heading_are_offset():
    """Kills: a key other than ``x``, ``y``, ``heading_deg`` offset (one that sorts before
    ``heading_deg``, as a ``depth`` key would: no registered vehicle has one, so a stand-in
    loop that has only ``initial_keys``)."""
    from types import SimpleNamespace

    loop = SimpleNamespace(initial_keys={"depth": 3.0, "heading_deg": 10.0, "x": 1.0, "z": 2.0})
    got = dict(scenario_spec(loop, position_offset=2.0, heading_offset=math.pi / 2).initial.values)
    assert got == {"x": (-1.0, 3.0), "heading_deg": pytest.approx((-80.0, 100.0), rel=1e-15)}


def test_sample_scenarios_refuses_bad_arguments_before_any_work():
    """Kills: the batch size's check (a float, zero), ``spec`` given with distribution keywords,
    the keyword-only ``loop``, ``nominal``, ``dtype``; ``Nominal`` frozen."""
    for bad in (0, -1, 2.5, "2"):
        with pytest.raises(ValueError, match=r"^n: expected a positive int"):
            sample_scenarios(0, bad)
    spec = scenario_spec(default_loop())
    with pytest.raises(TypeError, match=r"spec given, and also \['current_max'\]"):
        sample_scenarios(0, 2, spec, current_max=1.0)
    with pytest.raises(TypeError):
        sample_scenarios(0, 2, spec, default_loop())
    with pytest.raises(dataclasses.FrozenInstanceError):
        Nominal().plant = 1


def test_a_model_error_perturbs_each_scenario_s_plant_not_the_design():
    """Kills: the model fields dropped when the relative error is not 0 (every plant would
    then be the design). relative 0.2 on the mass only: factors in [0.8, 1.2], one per
    scenario."""
    b = sample_scenarios(0, 4, extra={"model_error": 0.2, "model_fields": ("mass",)})
    nominal = default_loop().default_params()
    ratio = np.asarray(b.plant.mass) / float(nominal.mass)
    assert ratio.shape == (4,) and np.all(np.abs(ratio - 1.0) <= 0.2)
    assert np.ptp(ratio) > 0.05
    assert float(b.design.mass) == float(nominal.mass)
    np.testing.assert_array_equal(b.plant.Iz, np.broadcast_to(nominal.Iz, (4,)))


def test_every_batched_field_of_a_batch_has_the_leading_axis(batch):
    """Kills: an entry of ``SCENARIO_AXES`` moved off 0 (the sea's, the origin depth's, the
    environment's: fields a plain batch leaves at None, so no sampled batch here sees them).
    The module's contract is a leading batch axis on every field but ``path`` and ``design``:
    ``scenario_at``, ``concat_batches`` and ``shard_scenarios`` index and split that axis,
    whatever ``SCENARIO_AXES`` says."""
    shared = ("path", "design")
    want = {f: None if f in shared else 0 for f in loops.Scenario._fields}
    assert SCENARIO_AXES._asdict() == want
    for f in loops.Scenario._fields:
        if f not in shared:
            leaves = jax.tree_util.tree_leaves(getattr(batch, f))
            assert all(jnp.shape(a)[0] == N_SAMPLE for a in leaves), f
    assert batch_size(batch) == N_SAMPLE


def test_a_batch_is_left_on_one_device_unless_it_splits_evenly(batch):
    """Kills: ``shard_scenarios`` sharding over one device, or a batch whose size is not a
    multiple of the device count (padding would change the mean), or miscounting the devices
    it used. (The sharding itself over two devices: tests/test_tuning.py's subprocess tests.)"""
    (d,) = jax.local_devices()[:1]
    three = _part(batch, 0, 3)
    for devices in ([d], [d, d]):
        same, n = shard_scenarios(three, devices)
        assert same is three and n == 1
    same, n = shard_scenarios(batch, [d])
    assert same is batch and n == 1


# ------------------------------------------------------------------ the loss's arguments


def test_loss_weights_defaults_dtype_and_refusals():
    """Kills: a default weight changed, a check skipped or its bound moved (0 is a valid weight,
    ``sat_width`` must be > 0), the dtype ignored."""
    w = loss_weights()
    assert {k: float(getattr(w, k)) for k in w._fields} == {
        "eps": 1.0, "u_tilde": 1.0, "psi_tilde": 1.0, "sat_excess": 1.0, "sat_time": 5.0,
        "effort": 0.0, "unhealthy": 1000.0, "sat_width": 0.05, "depth": 0.0,
    }  # fmt: skip
    # one default for Python and for a config file that omits [weights]
    from tuning.spec import Weights

    assert {k: float(getattr(w, k)) for k in w._fields} == {
        f.name: f.default for f in dataclasses.fields(Weights)
    }
    assert all(getattr(w, k).dtype == jnp.float64 for k in w._fields)
    w32 = loss_weights(jnp.float32, eps=0.0, depth=2)
    assert w32.eps.dtype == jnp.float32 and float(w32.eps) == 0.0 and float(w32.depth) == 2.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'bogus'"):
        loss_weights(eps=1.0, zzz=2.0, bogus=1.0)  # the first unknown name, sorted
    for k in ("eps", "unhealthy", "depth", "sat_width"):
        for bad in (True, "1", None):
            with pytest.raises(ValueError, match=rf"^weights\.{k}: expected a number"):
                loss_weights(**{k: bad})
        for bad in (-1e-3, math.inf, math.nan):
            with pytest.raises(ValueError, match=rf"^weights\.{k}: expected a finite value >= 0"):
                loss_weights(**{k: bad})
    with pytest.raises(ValueError, match=r"^weights\.sat_width: expected > 0, got 0"):
        loss_weights(sat_width=0)
    assert float(loss_weights(sat_width=np.float32(1e-3)).sat_width) == pytest.approx(1e-3)
    assert LossWeights(*[1.0] * 8).depth == 0.0  # built without depth (older code): weight 0


def test_tuning_problem_checks_and_passes_on_its_settings():
    """Kills: a check of ``TuningProblem`` skipped or its bound moved (alpha in (0, 1]), a
    setting not passed on to the rollout or the loop (smooth)."""
    space = GainSpace()
    for bad in ({"risk": "max"}, {"alpha": 0.0}, {"alpha": 1.5}, {"alpha": -0.2}):
        with pytest.raises(ValueError, match=f"^{next(iter(bad))}: expected"):
            TuningProblem(space=space, **bad)
    assert TuningProblem(space=space, risk="cvar", alpha=1.0).alpha == 1.0
    with pytest.raises(ValueError, match="num_steps"):
        TuningProblem(space=space, num_steps=0)
    p = TuningProblem(space=space, num_steps=7, integrator="heun", timing="sampled",
                      checkpoint=True, checkpoint_every=3, smooth=False)  # fmt: skip
    cfg = p.rollout_config()
    assert (cfg.num_steps, cfg.integrator, cfg.timing) == (7, "heun", "sampled")
    assert (cfg.checkpoint, cfg.checkpoint_every) == (True, 3)
    assert p.loop.smooth is False and TuningProblem(space=space).loop.smooth is True
    assert p.loop.vehicle == space.loop.vehicle
    d = TuningProblem(space=space)
    assert (d.num_steps, d.integrator, d.timing, d.risk, d.alpha) == (
        800, "rk4", "continuous", "mean", 0.2,
    )  # fmt: skip
    assert (d.checkpoint, d.checkpoint_every, d.tile_gains, d.surface) == (True, 1, False, False)
    assert hash(p) == hash(dataclasses.replace(p))  # static: a jit argument, a cache key
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.num_steps = 8


def test_problem_data_defaults_dtype_and_refusals():
    """Kills: ``problem_data``'s defaults (dt 0.1 s, log_box 3, box weight 10, the loop's
    default gains, the default weights), its checks, the dtype of the base gains."""
    problem = TuningProblem(space=GainSpace(), num_steps=5)
    d = problem_data(problem)
    assert (float(d.dt), float(d.log_box), float(d.box_weight)) == (0.1, 3.0, 10.0)
    np.testing.assert_array_equal(
        d.theta_ref, problem.space.encode(problem.space.loop.default_gains())
    )
    assert float(d.weights.sat_excess) == 1.0 and float(d.weights.sat_time) == 5.0
    assert d.dt.dtype == jnp.float64
    for name in ("dt", "log_box", "box_weight"):
        for bad in (0.0, -1.0, math.inf, math.nan):
            with pytest.raises(ValueError, match=f"^{name}: expected a finite value > 0"):
                problem_data(problem, **{name: bad})
    base32 = jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float32), d.base)
    d32 = problem_data(problem, base=base32, dt=0.05)
    assert d32.dt.dtype == jnp.float32 and d32.log_box.dtype == jnp.float32
    assert float(d32.dt) == pytest.approx(0.05)


def test_cvar_of_a_tiny_alpha_is_the_worst_and_of_alpha_one_the_mean():
    """Kills: CVaR's count floor of one scenario (a tiny alpha would average none: NaN), its
    rounding (ceil, the 1e-9 guard against alpha B landing just above an integer)."""
    losses = jnp.asarray([1.0, 5.0, 2.0, 8.0, 3.0])
    cvar = lambda a: float(aggregate(losses, TuningProblem(num_steps=5, risk="cvar", alpha=a)))
    assert cvar(1e-12) == 8.0 and cvar(1.0) == pytest.approx(3.8)
    assert cvar(0.6) == pytest.approx(16.0 / 3.0) and cvar(0.61) == pytest.approx(4.5)
    assert cvar(0.2 * 3) == pytest.approx(16.0 / 3.0)  # 0.6000000000000001 * 5: still 3


# ------------------------------------------------------------------ robust tuning's bookkeeping
# (tuning/robust.py without its searches: vcjax.search.falsify replaced by a stand-in; the
# searches themselves are tests/test_robust.py's, slow)

ROBUST = dict(adversarial_every=3, adversarial_count=2, starts=4, budget=5, step_size=0.25,
              seed=7, check_starts=6, check_budget=8, check_seed=1007, compare=False)  # fmt: skip


def _part(batch, lo, hi):
    """Scenarios lo..hi-1 of a batch (the shared fields as they are)."""
    return jax.tree_util.tree_map(
        lambda ax, a: a if ax is None else jax.tree_util.tree_map(lambda x: x[lo:hi], a),
        SCENARIO_AXES,
        batch,
        is_leaf=lambda x: x is None,
    )


def test_the_tuning_loss_metric_folds_segments_into_the_scenario_loss():
    """Kills: a segment's terms summed without their length, the average over the wrong count,
    the weights of another section (``of_table``: the tune's ``[weights]`` defaults, not the
    Python API's), a bad weight let through."""
    m = TuningLossMetric.of({"eps": 2.0, "sat_width": W, "depth": 3.0})
    assert m.name == "tuning_loss" and dict(m.weights)["eps"] == 2.0
    assert hash(m) == hash(TuningLossMetric.of({"depth": 3.0, "eps": 2, "sat_width": W}))  # static
    acc = m.init(jnp.float64)
    assert sorted(acc) == sorted(TERMS) and all(float(v) == 0.0 for v in acc.values())
    acc = m.update(acc, _Traj(), _signals(), jnp.arange(4))  # two segments of 4 steps, then
    acc = m.update(acc, _Traj(), _signals(), jnp.arange(4, 8))  # the mean over the 8 steps
    one = rollout_terms(_Traj(), _signals(), W)
    want = float(weighted_loss(one, loss_weights(eps=2.0, sat_width=W, depth=3.0)))
    assert float(m.value(acc, 8)) == pytest.approx(want, rel=1e-13)
    half = m.update(m.init(jnp.float64), _Traj(), _signals(), jnp.arange(4))
    assert float(m.value(half, 8)) == pytest.approx(want / 2, rel=1e-13)
    tab = dict(TuningLossMetric.of_table({"eps": 2.0}).weights)
    assert (tab["eps"], tab["sat_excess"], tab["sat_time"]) == (2.0, 1.0, 5.0)
    with pytest.raises(ValueError, match=r"weights\.eps"):
        TuningLossMetric.of({"eps": -1.0})


def test_concat_batches_puts_b_after_a_and_keeps_a_s_shared_fields(batch):
    a, b = _part(batch, 0, 3), _part(batch, 3, 5)
    both = concat_batches(a, b)
    for f in ("eta0", "nu0", "current", "u_d", "varpi0", "disturbance"):
        np.testing.assert_array_equal(getattr(both, f), getattr(batch, f)[:5], err_msg=f)
    assert both.path is a.path and both.design is a.design


def _robust_search(section=None, value=(1.0, np.nan, 3.0, 2.0), smooth=False):
    """A RobustSearch whose falsify answers ``value`` per start (no search run)."""
    from types import SimpleNamespace as NS

    sec = NS(**(section or ROBUST))
    env = NS(searched=("current_speed",), as_dict=lambda: {"current_speed": [0.0, 1.0]})
    setting = NS(loop=NS(smooth=True, name="train"))
    check = NS(loop=NS(smooth=smooth, name="check"))
    return RobustSearch(sec, env, setting, check, TuningLossMetric.of({}))


def test_a_robust_search_keeps_the_worst_it_found_and_moves_on(monkeypatch):
    """Kills: the search's arguments (budget, step size, starts, a new first scenario each
    round), the order of the worst (a NaN value counts as the worst), the slot's size, what a
    round records."""
    from types import SimpleNamespace as NS

    import tuning.robust as robust

    calls = []
    value = np.asarray([1.0, np.nan, 3.0, 2.0])

    def falsify(loop, gains, envelope, metric, setting, **kw):
        calls.append((loop.name, gains, kw))
        x = np.arange(8.0).reshape(4, 2)
        return NS(value=value, x=x, index=np.asarray([10, 11, 12, 13]), rollouts=20)

    monkeypatch.setattr(robust, "falsify", falsify)
    rs = _robust_search()
    x, index = rs.search("g", 6)
    np.testing.assert_array_equal(index, [11, 12])  # NaN first, then 3.0
    np.testing.assert_array_equal(x, [[2.0, 3.0], [4.0, 5.0]])
    kw = calls[0][2]
    assert calls[0][:2] == ("train", "g") and kw["first_index"] == 0
    assert (kw["starts"], kw["steps"], kw["step_size"]) == (4, 5, 0.25)
    assert kw["random_rollouts"] == 0 and kw["stop"]() is False
    assert rs.rounds[0]["step"] == 6 and rs.rounds[0]["first_index"] == 0
    assert rs.rounds[0]["rollouts"] == 20 and np.isnan(rs.rounds[0]["worst"])
    assert rs.rounds[0]["values"][1] == 3.0 and len(rs.rounds[0]["values"]) == 2
    rs.search("g", 9)
    assert calls[1][2]["first_index"] == 4 and rs.rounds[1]["first_index"] == 4
    value[:] = [1.0, 5.0, 3.0, 2.0]
    rs.search("g", 12)
    assert rs.rounds[2]["worst"] == 5.0 and rs.rounds[2]["values"] == [5.0, 3.0]


def test_the_independent_check_searches_the_held_out_plant(monkeypatch):
    from types import SimpleNamespace as NS

    import tuning.robust as robust

    seen = {}

    def falsify(loop, gains, envelope, metric, setting, **kw):
        seen.update(kw, loop=loop.name)
        row = {"tuning_loss": 4.5, "params": {"current_speed": 0.9}, "index": 3}
        return NS(metric="tuning_loss", rollouts=48, scenarios=lambda k: [row] * k)

    monkeypatch.setattr(robust, "falsify", falsify)
    got = _robust_search().check("g")
    assert got == {"worst": 4.5, "params": {"current_speed": 0.9}, "index": 3, "rollouts": 48}
    assert seen["loop"] == "check" and (seen["starts"], seen["steps"]) == (6, 8)
    assert seen["step_size"] == 0.25 and seen["random_rollouts"] == 0 and not seen["stop"]()


def test_the_refresh_hook_fills_the_slot_every_k_steps_only(batch, monkeypatch):
    rs = _robust_search()
    train, slot = _part(batch, 0, 3), _part(batch, 3, 5)
    asked = []

    def fake_slot(gains, k, progress=None):
        asked.append((gains, k))
        return slot

    monkeypatch.setattr(rs, "slot", fake_slot)
    hook = rs.refresh(train, lambda th: ("gains", th), lambda b: ("placed", b))
    for k in (0, 1, 2, 4, 5, 7):
        assert hook(k, "th", ("data", "old", "x")) is None, k
    new = hook(6, "th", ("data", "old", "x"))
    assert asked == [(("gains", "th"), 6)] and new[0] == "data" and new[2:] == ("x",)
    assert new[1][0] == "placed"
    np.testing.assert_array_equal(new[1][1].eta0, batch.eta0[:5])


def test_the_robust_block_reports_relative_changes():
    rs = _robust_search()
    mine = {"heldout_mean": 2.0, "worst": 6.0}
    out = report(rs, mine, None)
    assert out["robust"] is mine and out["nominal"] is None and "change" not in out
    s = out["search"]
    assert s["metric"] == "tuning_loss" and s["searched"] == ["current_speed"]
    assert s["envelope"] == {"current_speed": [0.0, 1.0]}
    t = s["training"]
    assert (t["adversarial_every"], t["adversarial_count"], t["starts"]) == (3, 2, 4)
    assert (t["budget"], t["step_size"], t["seed"], t["rounds"]) == (5, 0.25, 7, [])
    c = s["check"]
    assert (c["starts"], c["budget"], c["seed"]) == (6, 8, 1007)
    assert c["plant"] == "hard-clipped (as the held-out batch)"
    assert report(_robust_search(smooth=True), mine, None)["search"]["check"]["plant"] == (
        "smooth saturation"
    )
    change = report(rs, mine, {"heldout_mean": -4.0, "worst": 8.0})["change"]
    assert change["worst"] == pytest.approx(-0.25) and change["heldout_mean"] == 1.5
    assert report(rs, mine, {"heldout_mean": 0.0, "worst": 8.0})["change"]["heldout_mean"] is None
    rs.metric = "max_e"
    assert report(rs, mine, None)["search"]["metric"] == "max_e"


# ------------------------------------------------------------------ the config's declarations


def test_the_documented_defaults_are_the_defaults():
    """Kills: a default of a tune section changed (tuning/spec.py) without its documentation:
    the TOML example of ``tuning.config``'s docstring (the configuration's own page) names every
    key of every tune section with its default (``[model_error] fields``, commented out, has
    none); an empty config takes them."""
    import tomllib

    import tuning.config as tc
    from tuning.spec import DEFAULTS

    block = tc.__doc__.split("::\n", 1)[1]
    documented = tomllib.loads("\n".join(line[4:] for line in block.splitlines()))
    for section, keys in DEFAULTS.items():
        want = {k: v for k, v in keys.items() if (section, k) != ("model_error", "fields")}
        assert documented[section] == want, section
    cfg = tc.validate_config({}).to_dict()
    assert cfg["problem"] == DEFAULTS["problem"] | {"variant": "vcm_integral"}  # the vehicle's
    for section in ("weights", "scenarios", "train", "heldout", "optimizer"):
        assert cfg[section] == DEFAULTS[section], section
    assert cfg["report"] == DEFAULTS["report"] and "robust" not in cfg


#: (section, key, kind): "pos" > 0, "nonneg" >= 0, "ge1" an int >= 1, "ge0" an int >= 0
BOUNDS = [
    *[("problem", k, "pos") for k in ("horizon", "dt", "alpha", "log_box", "box_weight")],
    ("problem", "checkpoint_every", "ge1"),
    *[("weights", k, "nonneg") for k in ("eps", "u_tilde", "psi_tilde", "sat_excess")],
    *[("weights", k, "nonneg") for k in ("sat_time", "effort", "unhealthy", "depth")],
    ("weights", "sat_width", "pos"),
    *[("scenarios", k, "nonneg") for k in ("current_max", "position_offset")],
    ("scenarios", "heading_offset_deg", "nonneg"),
    ("train", "size", "ge1"),
    ("heldout", "size", "ge1"),
    *[("optimizer", k, "ge1") for k in ("steps", "memory_size", "max_linesearch_steps")],
    ("optimizer", "max_bad_steps", "ge1"),
    ("optimizer", "learning_rate", "pos"),
    ("optimizer", "grad_tol", "nonneg"),
    ("report", "plot_scenarios", "ge0"),
    *[("robust", k, "ge1") for k in ("adversarial_every", "adversarial_count", "budget")],
    *[("robust", k, "ge1") for k in ("starts", "check_starts", "check_budget")],
    ("robust", "step_size", "pos"),
]


def test_each_bounded_key_takes_its_bound_and_refuses_beyond():
    """Kills: a key's lower bound moved, made closed where it is open (or open where closed),
    CVaR's alpha allowed above 1 or refused at 1, a gain group named twice (parsed by the one
    validator, as a config file is)."""
    from tuning.spec import _OPTIONAL, _SECTIONS
    from vcjax.config import ConfigError, parse_section

    classes = {**_SECTIONS, **_OPTIONAL}
    takes = {"pos": (1e-3, 0.5), "nonneg": (0.0, 1e-3), "ge1": (1, 2), "ge0": (0, 1)}
    refuses = {"pos": (0.0, -1e-3), "nonneg": (-1e-3, -1.0), "ge1": (0, -1), "ge0": (-1,)}
    for section, k, kind in BOUNDS:
        for v in takes[kind]:
            assert getattr(parse_section(classes[section], {k: v}, section), k) == v
        for v in refuses[kind]:
            with pytest.raises(ConfigError, match=rf"\[{section}\] {k}"):
                parse_section(classes[section], {k: v}, section)
    assert parse_section(classes["problem"], {"alpha": 1.0}, "problem").alpha == 1.0
    with pytest.raises(ConfigError, match=r"\[problem\] tune: duplicate names"):
        parse_section(classes["problem"], {"tune": ["P_G", "P_G"]}, "problem")
    with pytest.raises(ConfigError, match=r"\[problem\] alpha"):
        parse_section(classes["problem"], {"alpha": 1.01}, "problem")


def test_a_tune_config_reads_as_a_mapping_and_round_trips():
    """Kills: the plain-dict fields read as frozen sections, ``robust`` recorded (or dropped)
    wrongly, ``from_dict`` losing a section."""
    from tuning.config import validate_config
    from tuning.spec import TuneConfig

    raw = {
        "scenario": {"vehicle": "odin", "controller": "vcm"},
        "waves": {"hs": [0.5, 1.0], "tp": [6.0, 8.0]},
        "initial": {"x": [-1.0, 1.0]},
        "current": {"speed": [0.0, 0.3]},
        "robust": {"seed": 3},
        "train": {"size": 3},
    }
    cfg = validate_config(raw)
    assert cfg["current"]["speed"] == [0.0, 0.3] and cfg["initial"] == {"x": [-1.0, 1.0]}
    assert cfg["waves"]["hs"] == [0.5, 1.0] and cfg["scenario"]["vehicle"] == "odin"
    assert cfg["train"]["size"] == 3 and cfg["problem"]["horizon"] == 80.0
    assert cfg.to_dict()["robust"]["seed"] == 3
    assert TuneConfig.from_dict(cfg.to_dict()) == cfg
    plain = validate_config({})
    assert plain["waves"] is None and "robust" not in plain.to_dict()
    assert TuneConfig.from_dict(plain.to_dict()) == plain


# ------------------------------------------------------------------ the gain space


def test_gain_space_refuses_what_it_cannot_tune():
    """Kills: a check of ``GainSpace`` skipped (not a loop, a duplicate, nothing to tune, a
    part of the gains where the whole are needed)."""
    with pytest.raises(ValueError, match="^loop: expected a vcjax.loops.Loop, got str"):
        GainSpace(loop="infante")
    with pytest.raises(ValueError, match=r"^tune: duplicate names in \['Delta', 'Delta'\]"):
        GainSpace(tune=("Delta", "Delta"))
    with pytest.raises(ValueError, match="^tune: nothing to tune"):
        GainSpace(tune=())
    space = GainSpace(tune=("sigma",))
    assert space.size == 1 and space.labels() == ["sigma"]
    full = loops.infante_gains()
    assert space.check_gains(full) is full
    with pytest.raises(
        ValueError, match=r"^where: expected the whole gains of .*\(InfanteGains\), got PMGains"
    ):
        space.check_gains(full.vcm, "where")
    with pytest.raises(ValueError, match="expected the whole gains"):
        space.encode(full.vcm)


def test_encode_clips_zero_and_saturated_gains_to_finite_theta():
    """Kills: the floors that keep ``encode`` finite (a positive gain of 0 -> log(1e-12), a
    bounded gain at 0 or at its cap -> 1e-6 inside), the cap FRAC_MAX = 0.95 of the bound."""
    space = GainSpace(tune=("sigma", "P_int"))
    full = loops.infante_gains()
    vcm = full.vcm
    bound = np.asarray(rh_bound(vcm.P_G, vcm.P_Phi))
    assert FRAC_MAX == 0.95
    at_cap = full._replace(vcm=vcm._replace(sigma=jnp.asarray(0.0), P_int=0.95 * bound * 2))
    th = np.asarray(space.encode(at_cap))
    logit = lambda f: math.log(f) - math.log1p(-f)  # noqa: E731
    np.testing.assert_allclose(th, [math.log(1e-12), logit(1 - 1e-6), logit(1 - 1e-6)], rtol=1e-12)
    zero = full._replace(vcm=vcm._replace(P_int=jnp.zeros(2)))
    np.testing.assert_allclose(space.encode(zero)[1:], logit(1e-6), rtol=1e-12)
    half = full._replace(vcm=vcm._replace(P_int=0.95 * bound / 2))
    np.testing.assert_allclose(space.encode(half)[1:], 0.0, atol=1e-12)
    g = space.decode(jnp.asarray([0.0, 0.0, 0.0]), full).vcm  # sigmoid(0) = 1/2 of the cap
    np.testing.assert_allclose(g.P_int, 0.95 * bound / 2, rtol=1e-14)
    assert float(g.sigma) == 1.0


def test_start_is_the_encoding_plus_the_symmetry_break_and_describe_decodes():
    """Kills: ``start`` without its offset or with another ``eps`` (default 0.1), ``describe``
    not decoding ``theta``."""
    space = GainSpace()
    full = loops.infante_gains()
    th0 = np.asarray(space.encode(full))
    off = space.symmetry_break(full)
    assert sorted(off[off != 0]) == [-0.1, -0.1, 0.1, 0.1]
    np.testing.assert_array_equal(space.start(full), th0 + off)
    half = GainSpace(tune=("P_G", "Delta"))  # P_G's partner P_Phi not tuned: no offset
    np.testing.assert_array_equal(half.symmetry_break(full), np.zeros(half.size))
    np.testing.assert_allclose(space.start(full, eps=0.3), th0 + 3 * off, rtol=1e-15, atol=1e-15)
    d = space.describe(th0 + np.log(2.0) * (np.asarray(space.labels()) == "Delta"), full)
    assert d["Delta"] == pytest.approx(10.0) and d["sigma"] == pytest.approx(0.5)
    assert d["P_G"] == pytest.approx([1.0, 0.5, 0.5])


def _robust_build(metric="loss", spec=None, weights=None):
    from types import SimpleNamespace as NS

    loop = default_loop()
    problem = TuningProblem(space=GainSpace(), num_steps=5, integrator="euler", timing="sampled")
    held = dataclasses.replace(problem, smooth=False)
    p, coeffs = loop.default_params(), type(loop).default_path()[1]
    section = NS(metric=metric, seed=7, check_seed=1007)
    spec = scenario_spec(loop) if spec is None else spec
    return RobustSearch.build(section, spec, problem, held, (p, p, coeffs), weights or {}, 0.1)


def test_a_robust_search_is_built_from_the_tune_s_own_settings():
    """Kills: the training and held-out settings swapped or not those of the problems (steps,
    integrator, timing, checkpointed, no sensor noise, no sea without waves, the seeds), the
    tuning loss not recognised by either name, a sweep metric's name not checked, the refusals
    (nothing to search, a further environment component)."""
    from vcjax.config import ConfigError

    rs = _robust_build(weights={"eps": 2.0})
    assert isinstance(rs.metric, TuningLossMetric) and dict(rs.metric.weights)["eps"] == 2.0
    assert isinstance(_robust_build("tuning_loss").metric, TuningLossMetric)
    for s, seed, smooth in ((rs.setting, 7, True), (rs.check_setting, 1007, False)):
        c = s.config
        assert (c.num_steps, c.integrator, c.timing, c.checkpoint) == (5, "euler", "sampled", True)
        assert s.seed == seed and s.loop.smooth is smooth and s.sea is None and s.dt == 0.1
        assert s.noise_std and set(s.noise_std) == {0.0}
    assert "initial.heading_deg" in rs.envelope.searched and rs.rounds == []
    with pytest.raises(
        ConfigError, match=r"\[robust\] metric: unknown metric 'bogus'.*; or tuning"
    ):
        _robust_build("bogus")
    loop = default_loop()
    fixed = dict(current_direction_deg=(0.0, 0.0))
    none = scenario_spec(loop, current_max=0, position_offset=0, heading_offset=0, extra=fixed)
    with pytest.raises(ConfigError, match="no range to search"):
        _robust_build(spec=none)
    force = {"environment": (("force", {"tau_0": [-1.0, 1.0]}),)}
    with pytest.raises(ConfigError, match="further environment components cannot be searched"):
        _robust_build(spec=scenario_spec(loop, extra=force))


ROBUST_TOML = """
[robust]
adversarial_every = 2
adversarial_count = 2
starts = 3
budget = 4
"""


def test_a_robust_tune_attaches_its_slot_refreshes_it_and_reports(tmp_path, batch, monkeypatch):
    """Kills: the adversarial slot's first search against other gains or at another step, the
    nominal parameters of the searches (the config's design, plant and path, not the loop's
    defaults), the batch not extended by the slot, the hook's announcements (the latest
    round's), the independent check's block and, with ``compare``, the nominal run's folder.
    ``RobustSearch.slot`` and ``check`` and the nominal tune replaced: no search, no tune."""
    from types import SimpleNamespace

    import tuning.robust as robust
    from tuning.scenarios import config_spec

    slots, said = [], []

    def slot(self, gains, step, progress=None):
        slots.append((gains, step))
        self.rounds.append({"worst": 2.5 + step})
        return _part(batch, 0, 2)

    monkeypatch.setattr(robust.RobustSearch, "slot", slot)
    monkeypatch.setattr(robust.RobustSearch, "check", lambda self, g, progress=None: {"worst": 9})
    (tmp_path / "p.json").write_text(json.dumps({"mass": 3000.0}))
    (tmp_path / "plant.json").write_text(json.dumps({"Iz": 5000.0}))
    path = tmp_path / "r.toml"
    scenario = '[scenario]\nparams = "p.json"\nplant_params = "plant.json"\n'
    scenario += '[scenario.path]\nkind = "circle"\nradius = 40.0\n'
    text = TUNE.format(train=0, heldout=1001, heldout_size=4, steps=3)
    path.write_text(scenario + text + ROBUST_TOML)
    cfg = load_config(path)
    problem = TuningProblem(space=GainSpace(), num_steps=10, integrator="euler", timing="sampled")
    held = dataclasses.replace(problem, smooth=False)
    data = problem_data(problem)
    t = SimpleNamespace(cfg=cfg, problem=problem, eval_problem=held, data=data)
    t.train = _part(batch, 0, 4)
    t.start = data.theta_ref + problem.space.symmetry_break(data.base)
    t.robust, train = robust.attach(t, t.start, said.append, config_spec)
    assert batch_size(train) == 6
    np.testing.assert_array_equal(train.eta0[:4], batch.eta0[:4])
    np.testing.assert_array_equal(train.eta0[4:], batch.eta0[:2])
    want = problem.space.values(problem.space.decode(t.start, data.base))
    assert problem.space.values(slots[0][0]) == want and slots[0][1] == 0
    plant, design, coeffs = t.robust.setting.nominal
    nominal = problem.space.loop.default_params()
    assert float(design.mass) == 3000.0 and float(design.Iz) == float(nominal.Iz)
    assert float(plant.mass) == 3000.0 and float(plant.Iz) == 5000.0
    for a, b in zip(jax.tree.leaves(coeffs), cfg.scenario.coeffs(), strict=True):
        np.testing.assert_array_equal(a, b)
    assert any("every 2 steps, a search (3 starts x 4 steps of tuning_loss over" in m for m in said)
    assert "puts its 2 worst scenarios" in said[-2] and said[-1] == "robust: worst found 2.5"
    refresh = robust.hook(t, said.append, tcli.distribute)
    assert refresh(1, t.start, (data, train)) is None and len(slots) == 1
    new = refresh(2, t.start, (data, train))
    assert new[0] is data and batch_size(new[1]) == 6 and slots[1][1] == 2
    assert said[-1] == "robust: step 2: worst found 4.5"
    refresh(4, t.start, (data, train))
    assert said[-1] == "robust: step 4: worst found 6.5"
    block = robust.summarize(t, "tuned", {"loss": 1.5}, tmp_path, None, said.append, None)
    assert block["robust"] == {"heldout_mean": 1.5, "worst": 9} and block["nominal"] is None
    ran = []

    def nominal_tune(config_path, out, progress=None, cfg=None):
        ran.append((out, cfg.robust))
        out.mkdir()
        gains = problem.space.loop.gains_to_json(problem.space.loop.default_gains())
        (out / "gains.json").write_text(json.dumps(gains))
        return {"summary": {"heldout_loss_after": 3.0}}

    t.robust.section = dataclasses.replace(cfg.robust, compare=True)
    block = robust.summarize(t, "tuned", {"loss": 1.5}, tmp_path, None, said.append, nominal_tune)
    assert ran == [(tmp_path / "nominal", None)]
    assert block["nominal"] == {"heldout_mean": 3.0, "worst": 9}
    assert block["change"]["heldout_mean"] == -0.5 and block["change"]["worst"] == 0.0


def test_the_objective_adds_the_box_penalty_to_the_batch_loss(monkeypatch):
    """Kills: the box penalty subtracted (or dropped) from the objective. The scenario losses
    are replaced by fixed ones: no rollout."""
    import tuning.loss as tl

    losses, terms = jnp.asarray([1.0, 5.0, 2.0, 8.0, 3.0]), {"eps": jnp.zeros(5)}
    monkeypatch.setattr(tl, "scenario_losses", lambda th, d, s, p: (losses, terms))
    problem = TuningProblem(space=GainSpace(), num_steps=5)
    data = problem_data(problem, log_box=1.0, box_weight=10.0)
    theta = data.theta_ref.at[2].add(-1.5)  # 0.5 beyond the box
    loss, (got, t) = tl.objective(theta, data, None, problem)
    assert float(loss) == pytest.approx(3.8 + 10.0 * 0.25) and got is losses and t is terms


def test_simulation_keys_fold_into_the_problem_and_the_checks_that_span_sections():
    """Kills: ``[simulation]``'s horizon and dt not taken (or ``u_d`` taken as a ``[problem]``
    key), the one-step horizon refused (horizon = dt is one step), a Gauss-Markov current let
    through, the wave period checked at its longest instead of its shortest, two disagreeing
    spellings of the controller let through when the newer one sorts first."""
    from tuning.config import validate_config
    from vcjax.config import ConfigError

    cfg = validate_config({"simulation": {"horizon": 0.5, "dt": 0.5, "u_d": [1.0, 1.5]}})
    assert (cfg.problem.horizon, cfg.problem.dt) == (0.5, 0.5)
    assert cfg.simulation.u_d == (1.0, 1.5)
    with pytest.raises(ConfigError, match=r"\[simulation\] dt: also given as \[problem\] dt"):
        validate_config({"simulation": {"dt": 0.5}, "problem": {"dt": 0.5}})
    with pytest.raises(ConfigError, match=r"\[simulation\] horizon: must be >= dt \(0.5 s\)"):
        validate_config({"simulation": {"horizon": 0.4, "dt": 0.5}})
    with pytest.raises(ConfigError, match=r"\[current\] model: vcjax tune samples constant"):
        validate_config({"current": {"model": "gauss_markov"}})
    odin = {"scenario": {"vehicle": "odin"}, "simulation": {"dt": 0.1}}
    validate_config(odin | {"waves": {"hs": [0.5, 1.0], "tp": [4.0, 10.0]}})
    with pytest.raises(ConfigError, match=r"\[waves\] tp: the shortest wave period"):
        validate_config(odin | {"waves": {"hs": [0.5, 1.0], "tp": [3.9, 10.0]}})
    with pytest.raises(ConfigError, match=r"'vcm' contradicts \[scenario\] controller 'ilos'"):
        validate_config({"scenario": {"controller": "ilos"}, "problem": {"variant": "vcm"}})
    same = validate_config({"scenario": {"controller": "ilos"}, "problem": {"variant": "ilos"}})
    assert same.problem.variant == "ilos" and same.scenario.controller == "ilos"


# ------------------------------------------------------------------ the black-box baselines


def test_bayes_refuses_bad_arguments_and_keeps_to_its_defaults():
    """Kills: ``run_bayes``' checks (an empty or non-finite start, a box that is not finite and
    > 0, no candidate per batch) and its defaults (box 3, batches of 8, 1000 evaluations: 125
    batches announced); the seed's default (0) reproduces."""
    pytest.importorskip("optuna")
    from tuning.bayes import run_bayes

    f = lambda X: np.sum(np.asarray(X) ** 2, axis=1)  # noqa: E731
    for bad in ([], [0.0, np.nan]):
        with pytest.raises(ValueError, match="^theta0: expected a non-empty finite vector"):
            run_bayes(f, bad)
    for bad in (0.0, -1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="^box: expected a finite value > 0"):
            run_bayes(f, [0.0], box=bad)
    with pytest.raises(ValueError, match="^popsize: expected >= 1, got 0"):
        run_bayes(f, [0.0], popsize=0)
    seen, totals = [], []
    res = run_bayes(
        lambda X: seen.append(np.array(X)) or f(X),
        [1.0, -1.0],
        n_startup=40,
        progress=lambda gen, total, rec: totals.append(total),
        should_stop=lambda: len(seen) >= 4,
    )
    X = np.concatenate(seen)
    assert [s.shape for s in seen] == [(8, 2)] * 4 and set(totals) == {125}
    assert np.all(np.abs(X - [1.0, -1.0]) <= 3.0) and np.max(np.abs(X - [1.0, -1.0])) > 2.0
    again = run_bayes(f, [1.0, -1.0], seed=0, max_evals=32, n_startup=40)
    np.testing.assert_array_equal(res.theta, again.theta)
    sevens = []  # 1000 evaluations: 142 whole batches of 7 (1001 would make 143)
    run_bayes(f, [0.0], popsize=7, progress=lambda g, n, r: sevens.append(n),
              should_stop=lambda: bool(sevens))  # fmt: skip
    assert sevens == [142]
    one = run_bayes(f, [0.0], box=0.5, popsize=1, max_evals=2)  # the smallest valid ones
    assert one.evals == 2 and abs(float(one.theta[0])) <= 0.5
    with pytest.raises(TypeError):
        run_bayes(f, [0.0], 3.0)  # keyword-only
    with pytest.raises(ValueError):  # one value per candidate, or the batch is refused
        run_bayes(lambda X: f(X)[:-1], [0.0], max_evals=8)


def test_bayes_asks_optuna_for_a_joint_tpe_with_a_constant_liar(monkeypatch):
    """Kills: the sampler's settings (``multivariate``: the gains modelled jointly;
    ``constant_liar``: a batch's candidates spread out; the seed and the number of random
    start-up trials by default), which the results show only statistically."""
    optuna = pytest.importorskip("optuna")
    from tuning.bayes import run_bayes

    made = []
    real = optuna.samplers.TPESampler

    def sampler(**kw):
        made.append(kw)
        return real(**kw)

    monkeypatch.setattr(optuna.samplers, "TPESampler", sampler)
    run_bayes(lambda X: np.sum(np.asarray(X) ** 2, axis=1), [0.0], max_evals=8)
    assert made == [dict(seed=0, multivariate=True, constant_liar=True, n_startup_trials=10)]


def test_vehicle_and_robust_cross_checks_and_the_gains_file_path(tmp_path):
    """Kills: a current refused or let through by the wrong bound (any speed above 0 for a
    loop without currents), ``[robust] starts`` refused at ``adversarial_count`` (equal is
    enough), an actuator's ``max_abs_<name>`` refused (or an unknown metric let through), the
    initial gains' path not resolved against the config's folder."""
    from tuning.config import validate_config
    from vcjax.config import ConfigError

    arm = {"scenario": {"vehicle": "arm"}}
    validate_config(arm | {"scenarios": {"current_max": 0.0}})
    with pytest.raises(ConfigError, match=r"\[current\] the arm loop takes no current"):
        validate_config(arm | {"scenarios": {"current_max": 0.5}})
    rob = validate_config({"robust": {"starts": 2, "adversarial_count": 2}}).robust
    assert (rob.starts, rob.adversarial_count) == (2, 2)
    assert validate_config({"robust": {"metric": "max_abs_rudder"}}).robust.metric == (
        "max_abs_rudder"
    )
    with pytest.raises(ConfigError, match=r"\[robust\] metric: unknown metric 'bogus'"):
        validate_config({"robust": {"metric": "bogus"}})
    (tmp_path / "sub").mkdir()
    cfg = tmp_path / "sub" / "t.toml"
    cfg.write_text('[problem]\ninitial_gains = "g.json"\n')
    assert load_config(cfg).problem.initial_gains == str(tmp_path / "sub" / "g.json")
    absolute = tmp_path / "g.json"
    cfg.write_text(f'[problem]\ninitial_gains = "{absolute.as_posix()}"\n')
    assert load_config(cfg).problem.initial_gains == str(absolute)
