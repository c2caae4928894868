"""A new law for an existing vehicle is one file plus one registry line: a LOS + PD heading law
for ``infante`` with its own gains, written in a user's file outside the package
(``examples/laws/los_pd.py``), registered with :func:`vcjax.loops.register_law`, then simulated,
swept and tuned through the public API."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from tuning.loss import TuningProblem, objective, problem_data
from tuning.optim import run_gradient_tuner
from tuning.params import GainSpace
from tuning.scenarios import sample_scenarios as tuning_batch
from vcjax import loops
from vcjax.config.scenario import ScenarioChoice, import_module_file
from vcjax.rollout import RolloutConfig
from vcjax.sweep import ScenarioSpec, SweepSpec, run_sweep

# ------------------------------------------------------------------ the new law (one file)

# examples/laws/los_pd.py: the law, its gains and the one registry line, in a user's file
# outside the package (the how-to of docs/guides/own-law.md)
import_module_file(Path(__file__).resolve().parents[1] / "examples" / "laws" / "los_pd.py")
LosPDGains = type(loops.make_loop("infante", "los_pd").default_gains())

# ------------------------------------------------------------------ through the public API


def test_the_new_law_is_listed_and_simulated_with_its_own_gains():
    assert "los_pd" in loops.controllers("infante")
    loop = loops.make_loop("infante", "los_pd")
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


@pytest.mark.slow  # 7 s; test_howto sweeps this law through the CLI
def test_the_new_law_is_swept_and_tuned():
    choice = ScenarioChoice(vehicle="infante", controller="los_pd")
    spec = SweepSpec(
        num_scenarios=2,
        variants=("los_pd",),
        horizon=3.0,
        dt=0.1,
        chunk_size=2,
        record_points=5,
        choice=choice,
        scenario=ScenarioSpec(initial=(("y", (-2.0, 2.0)),)),
    )
    res = run_sweep(spec, progress=False)
    m = res.metrics["los_pd"]
    assert res.index.tolist() == [0, 1] and np.all(np.isfinite(m["max_abs_e"]))

    loop = spec.loop("los_pd")
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
