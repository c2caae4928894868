"""Path geometry shared by loops (vcjax.loops.geometry) against hand computations, and the
disturbance wrapper of :func:`vcjax.loops.simulate` (vcjax.loops.disturbances): no disturbance
is the plain rollout; zero noise and a zero-variance Gauss–Markov current change nothing; a
real one changes the run, reproducibly per key; what a loop cannot take is refused. A point
mass of this file's own, a few steps (tiny programs, compiled once per static setting)."""

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from planar_loops import PlanarPointMass

from vcjax import loops, paths
from vcjax.rollout import Reduction, RolloutConfig, rollout

# ------------------------------------------------------------------ geometry


def test_path_frames_and_errors_on_a_line_by_hand():
    # Simulation 1's line x = 10 travelled towards east (+y): psi_p = pi/2 everywhere
    path, c = paths.paper_line()
    frames = loops.path_frames(path, c, jnp.asarray([0.0, 3.0]))
    np.testing.assert_allclose(frames.p_bar, [[10.0, 0.0], [10.0, 3.0]], atol=1e-15)
    np.testing.assert_allclose(frames.psi_p, [math.pi / 2] * 2, rtol=1e-15)
    # R(pi/2)^T (p - p_bar) = [d_y, -d_x]: a point 2 m north of p(3) and 2 m further east
    # is 2 m ahead (s) and 2 m to the left of the path (e = -2: e is positive to the right)
    eps = loops.path_errors(frames, jnp.asarray([[10.0, 0.0, 0.0], [12.0, 5.0, 0.0]]))
    np.testing.assert_allclose(eps, [[0.0, 0.0], [2.0, -2.0]], atol=1e-14)


def test_path_errors_on_a_circle_are_radial():
    path, c = paths.circle(center=(1.0, 2.0), radius=3.0)  # clockwise seen from above
    w = jnp.asarray([0.0, 2.0, 5.0])
    frames = loops.path_frames(path, c, w)
    phi = np.asarray(w) / 3.0
    ray = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    np.testing.assert_allclose(frames.p_bar, [1.0, 2.0] + 3.0 * ray, atol=1e-14)
    eps = loops.path_errors(frames, jnp.asarray([1.0, 2.0] + 4.0 * ray))  # 1 m outside
    # on the particle's normal, no along-track error; outside a clockwise circle is its left
    np.testing.assert_allclose(eps, [[0.0, -1.0]] * 3, atol=1e-14)


def test_path_polyline_spans_what_it_says():
    path, c = paths.paper_line()
    pts = np.asarray(loops.path_polyline(path, c, points=[[0.0, -5.0], [3.0, 20.0]], num=36))
    assert pts.shape == (36, 3)
    np.testing.assert_allclose(pts[[0, -1]], [[10.0, -15.0, 0.0], [10.0, 30.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(np.diff(pts[:, 1]), 45.0 / 35, rtol=1e-12)  # evenly spaced
    path, c = paths.circle(center=(0.0, 0.0), radius=40.0)
    pts = np.asarray(loops.path_polyline(path, c, num=50))
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 40.0, rtol=1e-13)
    np.testing.assert_allclose(pts[0], pts[-1], atol=1e-9)  # exactly one turn
    np.testing.assert_allclose(np.asarray(loops.path_polyline(path, c, num=8))[0], pts[0])


def test_start_parameter_on_a_helix_and_a_survey():
    path, c = paths.paper_helix()
    w0 = 7.3
    on = paths.path_point(path, c, jnp.asarray(w0))
    start = jax.jit(lambda q: loops.start_parameter(path, c, q))
    assert float(start(on)) == pytest.approx(w0, abs=1e-8)
    path, c = paths.lawnmower((0.0, 0.0, 1.0), 100.0, 20.0, 3, 10.0, 50.0)
    w0 = 100.0 + math.pi * 20.0 + 40.0  # 40 m into the second leg
    p = np.asarray(paths.path_point(path, c, jnp.asarray(w0)))
    start = jax.jit(lambda q: loops.start_parameter(path, c, q))
    assert float(start(jnp.asarray(p + [0.0, 2.0, 0.0]))) == pytest.approx(w0, abs=1e-6)


# ------------------------------------------------------------------ disturbances


@dataclasses.dataclass(frozen=True)
class DriftLoop(PlanarPointMass, loops.EngineLoop):
    """A planar point mass in water (drag on the velocity relative to the current), with
    position and velocity sensors."""

    vehicle: ClassVar[str] = "unit_drift"
    initial_keys: ClassVar[dict[str, float]] = {"x": 0.0, "y": 1.0, "vx": 0.5, "vy": 0.0}
    noise_channels: ClassVar[dict[str, int]] = {"position_std": 2, "velocity_std": 2}
    defaults: ClassVar[tuple] = (2.0, 1.0, (10.0, 10.0))
    default_speed: ClassVar[float] = 0.5

    @classmethod
    def default_path(cls):
        return paths.line(origin=(0.0, 0.0), direction=(1.0, 0.0))

    def measure(self, x, noise):
        q, qd = x
        return q + noise[:2], qd + noise[2:]


loops.register(DriftLoop)
LOOP = loops.make_loop("unit_drift", "vcm")
SC = loops.make_scenario(LOOP, current=(0.0, 0.3))
GAINS = LOOP.default_gains()
CONFIG = RolloutConfig(num_steps=20)
DT = 0.05
_run = jax.jit(loops.simulate, static_argnames=("loop", "config", "dist"))


def _params(sigma=0.0, noise=0.0, seed=0):
    gm = loops.gauss_markov_params(SC, sigma, 30.0, 2.0)
    std = jnp.asarray(LOOP.noise_std({"position_std": noise, "velocity_std": noise}))
    return loops.DisturbanceParams(current=gm, noise_std=std, key=jax.random.PRNGKey(seed))


def _same(a, b, atol=0.0):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0, atol=atol)


def test_without_disturbances_simulate_is_the_loops_rollout():
    @jax.jit
    def both():  # one program holding both rollouts
        x0, z0 = LOOP.initial_state(SC)
        args = LOOP.plant_args(SC, SC.current, jnp.zeros(3))
        ctrl = LOOP.ctrl_params(GAINS, SC)
        ref = rollout(LOOP.plant, LOOP.control, CONFIG, args, ctrl, x0, z0, DT)
        return loops.simulate(LOOP, GAINS, SC, CONFIG, DT), ref

    _same(*both())
    assert not loops.Disturbances().active and loops.Disturbances(sensor_noise=True).active
    gm = loops.gauss_markov_params(SC, 0.1, 30.0, 2.0)
    np.testing.assert_array_equal(gm.mean, [0.0, 0.3])  # the mean: the horizontal current


BOTH = loops.Disturbances(gauss_markov=True, sensor_noise=True)


def test_zero_noise_and_a_zero_variance_current_change_nothing():
    plain = _run(LOOP, GAINS, SC, CONFIG, DT)
    _same(_run(LOOP, GAINS, SC, CONFIG, DT, BOTH, _params()), plain, atol=1e-14)


def test_noise_and_a_varying_current_change_the_run_reproducibly_per_key():
    plain = _run(LOOP, GAINS, SC, CONFIG, DT)
    a = _run(LOOP, GAINS, SC, CONFIG, DT, BOTH, _params(sigma=0.2, seed=1))
    assert np.max(np.abs(np.asarray(a.x[0] - plain.x[0]))) > 1e-6  # the water moved it
    _same(_run(LOOP, GAINS, SC, CONFIG, DT, BOTH, _params(sigma=0.2, seed=1)), a)
    b = _run(LOOP, GAINS, SC, CONFIG, DT, BOTH, _params(sigma=0.2, seed=2))
    assert not np.allclose(np.asarray(b.x[0]), np.asarray(a.x[0]))
    noisy = _run(LOOP, GAINS, SC, CONFIG, DT, BOTH, _params(noise=0.05))
    assert np.max(np.abs(np.asarray(noisy.u - plain.u))) > 1e-4  # the controller saw it


def test_what_a_loop_cannot_take_is_refused():
    arm = loops.make_loop("arm", "vcm")
    sc = loops.make_scenario(arm)
    with pytest.raises(ValueError, match=r"current: the arm loop cannot take a time-varying"):
        loops.simulate(arm, arm.default_gains(), sc, CONFIG, DT, loops.Disturbances(True))
    with pytest.raises(ValueError, match="dist_params: required with disturbances"):
        loops.simulate(LOOP, GAINS, SC, CONFIG, DT, loops.Disturbances(sensor_noise=True))


def test_a_reduction_folds_the_same_steps():
    """With a reduction the record is folded segment by segment: the sum of |e| over the run
    equals the one of the whole trajectory."""

    def update(acc, seg, ks):
        return acc + jnp.sum(jnp.abs(seg.aux.eps[:, 1])), None

    red = Reduction(init=jnp.zeros(()), update=update, segment=6)  # 20 = 6 + 6 + 6 + 2
    acc, _ = jax.jit(lambda: loops.simulate(LOOP, GAINS, SC, CONFIG, DT, reduction=red))()
    full = _run(LOOP, GAINS, SC, CONFIG, DT)
    np.testing.assert_allclose(float(acc), float(jnp.sum(jnp.abs(full.aux.eps[:, 1]))), rtol=1e-13)
