"""A new law for an existing vehicle is one file plus one registry line: a LOS + PD heading law
for ``infante``, defined entirely in this file with its own gains, registered with
:func:`vcjax.loops.register_law`, then simulated, swept and tuned through the public API."""

import dataclasses
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np
import pytest

from tuning.loss import TuningProblem, objective, problem_data
from tuning.optim import run_gradient_tuner
from tuning.params import GainSpace
from tuning.scenarios import sample_scenarios as tuning_batch
from vcjax import loops, paths
from vcjax.config.scenario import ScenarioChoice
from vcjax.linalg import rot2, wrap_angle
from vcjax.rollout import RolloutConfig
from vcjax.sweep import ScenarioSpec, SweepSpec, run_sweep

# ------------------------------------------------------------------ the new law (one file)


class LosPDGains(NamedTuple):
    Delta: Any  # () look-ahead [m]
    sigma: Any  # () particle-speed gain [1/s]
    k_u: Any  # () surge-speed gain [1/s]
    k_p: Any  # () heading stiffness [1/s^2]
    k_d: Any  # () heading damping [1/s]


class LosPDParams(NamedTuple):
    gains: LosPDGains
    path: Any
    u_d: Any
    model: Any


class LosPDState(NamedTuple):
    varpi: Any


class LosPDAux(NamedTuple):
    eps: Any
    psi_tilde: Any


@dataclasses.dataclass(frozen=True)
class LosPDLaw(loops.Law):
    """Particle on the path at ``u_d + sigma s``; heading to the LOS point ``Delta`` ahead,
    PD on the heading error; P on the surge speed (both through the design inertia)."""

    def default_gains(self, loop):
        f = lambda x: jnp.asarray(x, float)
        return LosPDGains(f(6.0), f(0.5), f(1.0), f(0.6), f(1.6))

    def gain_specs(self, loop):
        return tuple(loops.gain_spec(n) for n in LosPDGains._fields)

    def validate_gains(self, gains):
        if not all(float(g) > 0 for g in gains):
            raise ValueError("los_pd gains: every gain must be > 0")
        return gains

    def params(self, loop, gains, sc, model, k_rudder):
        return LosPDParams(gains, sc.path, sc.u_d, model)

    def initial_state(self, loop, sc):
        return LosPDState(varpi=sc.varpi0)

    def step(self, loop, params, t, x, z):
        g, m = params.gains, params.model
        frame = paths.path_pose(loop.path, params.path, z.varpi)  # no rates needed
        s, e = rot2(frame.psi_p).T @ (x.eta[:2] - frame.p[:2])
        psi_d = frame.psi_p + jnp.arctan2(-e, g.Delta)
        psi_tilde = wrap_angle(x.eta[2] - psi_d)
        tau_u = m.m11 * g.k_u * (params.u_d - x.nu[0]) + m.d11 * x.nu[0]
        tau_r = -m.m33 * (g.k_p * psi_tilde + g.k_d * x.nu[2])
        tau = jnp.stack([tau_u, jnp.zeros_like(tau_u), tau_r])
        w_dot = (params.u_d + g.sigma * s) / frame.speed_bar
        return tau, LosPDState(varpi=w_dot), LosPDAux(jnp.stack([s, e]), psi_tilde)


loops.register_law("infante", "los_pd_here", LosPDLaw())  # the one registry line

# ------------------------------------------------------------------ through the public API


def test_the_new_law_is_listed_and_simulated_with_its_own_gains():
    assert "los_pd_here" in loops.controllers("infante")
    loop = loops.make_loop("infante", "los_pd_here")
    g = loop.default_gains()
    assert isinstance(g, LosPDGains) and [s.name for s in loop.gain_specs()] == list(g._fields)
    back = loop.gains_from_json(loop.gains_to_json(g._replace(Delta=jnp.asarray(4.0))))
    assert float(back.Delta) == 4.0
    with pytest.raises(ValueError, match="must be > 0"):
        loop.gains_from_json({"k_p": -1.0})
    sc = loops.make_scenario(loop, initial={"y": 5.0, "heading_deg": 90.0})
    traj = loops.simulate(loop, g, sc, RolloutConfig(num_steps=300), 0.1)
    sig = loop.signals(traj, sc)
    e = np.asarray(sig.eps[:, 1])
    # the craft starts 10 m off the line [10, w] (x = 0) and the law brings it closer
    assert abs(e[0]) > 9.0 and abs(e[-1]) < 0.5 * abs(e[0])
    assert np.all(np.isfinite(np.asarray(sig.psi_err)))


def test_the_new_law_is_swept_and_tuned():
    choice = ScenarioChoice(vehicle="infante", controller="los_pd_here")
    spec = SweepSpec(
        num_scenarios=2,
        variants=("los_pd_here",),
        horizon=3.0,
        dt=0.1,
        chunk_size=2,
        record_points=5,
        choice=choice,
        scenario=ScenarioSpec(initial=(("y", (-2.0, 2.0)),)),
    )
    res = run_sweep(spec, progress=False)
    m = res.metrics["los_pd_here"]
    assert res.index.tolist() == [0, 1] and np.all(np.isfinite(m["max_abs_e"]))

    loop = spec.loop("los_pd_here")
    problem = TuningProblem(space=GainSpace(loop=loop), num_steps=30, timing="sampled")
    data = problem_data(problem, dt=0.1)
    train = tuning_batch(0, 2, loop=loop, position_offset=2.0, current_max=0.0)
    loss = lambda th, d, s: objective(th, d, s, problem)[0]
    r = run_gradient_tuner(
        loss, data.theta_ref, (data, train), optimizer="adam", steps=2, learning_rate=0.05
    )
    assert r.n_bad == 0 and np.isfinite(r.loss)
    # the gradient at the start (the tuner's first step, compiled once): finite, not zero
    g0 = r.history[0]["grad_norm"]
    assert g0 is not None and np.isfinite(g0) and g0 > 0
