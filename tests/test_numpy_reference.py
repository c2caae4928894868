"""Independent cross-check of Simulation 1's ``vcm_integral`` closed loop against the plain
NumPy model in ``tests/reference/numpy_reference.py`` (written from the equations, not from the JAX
code: closed-form line frame, closed-form underactuation condition, precomputed ``M^-1``).

Tolerance: every state entry at every step within ``1e-10 (1 + |x|)`` over 20 s (400 RK4 steps,
dt = 0.05 s) in float64; the observed difference is ~1e-13, i.e. round-off only.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from vcjax import experiments, loops
from vcjax.vehicles import infante

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.reference import numpy_reference as nr  # noqa: E402

RTOL = 1e-10
HORIZON, DT = 20.0, 0.05


def _vcjax_states(traj):
    x, z = traj.x, traj.z
    cols = [x.eta, x.nu, x.act, np.asarray(z.varpi)[:, None], np.asarray(z.v_d)[:, None], z.int_eps]
    return np.concatenate([np.asarray(c) for c in cols], axis=1)


def test_plant_parameters_rebuilt_from_the_docstring_match():
    p, q = infante.infante_params(), nr.plant_params()
    for name in q._fields:
        if hasattr(p, name):
            np.testing.assert_allclose(
                np.asarray(getattr(q, name)), np.asarray(getattr(p, name)), rtol=1e-12, err_msg=name
            )
    np.testing.assert_allclose(np.asarray(q.cf_k), float(p.cf_coeff * p.cf_dx), rtol=1e-12)
    np.testing.assert_allclose(
        np.linalg.inv(np.asarray(q.Minv)), np.asarray(infante.mass_matrix(p)), rtol=1e-12
    )


@pytest.mark.parametrize(
    "eta0, V_c",
    [
        ((0.0, 0.0, np.pi / 2), (0.0, 0.5)),  # the paper's scenario
        ((4.0, -3.0, 0.3), (0.3, -0.2)),  # other side of the path, cross current
    ],
)
def test_numpy_reference_matches_vcjax(eta0, V_c):
    sim1 = experiments.get("sim1")
    sc = loops.make_scenario(sim1.loop("vcm"), eta0=eta0, nu0=(2.0, 0.0, 0.0), current=V_c, u_d=2.0)
    traj = sim1.simulate("vcm_integral", sim1.setup(HORIZON, DT, V_c), scenario=sc)
    assert bool(np.all(np.asarray(traj.finite)))
    J = _vcjax_states(traj)
    n = int(round(HORIZON / DT))
    Y, SE = nr.simulate(n, DT, nr.Scenario(eta0=eta0, V_c=V_c))
    assert Y.shape == J.shape == (n + 1, 12)
    err = np.abs(Y - J) / (1.0 + np.abs(J))
    worst = int(np.argmax(err.max(axis=0)))
    assert err.max() < RTOL, f"{nr.STATE_NAMES[worst]}: relative error {err.max():.3g}"
    np.testing.assert_allclose(SE, np.asarray(traj.aux.eps), rtol=0, atol=RTOL * 100)
    # the run does something: the vehicle turns onto the path and travels along it
    assert abs(J[-1, 0] - 10.0) < 2.0 and J[-1, 1] > 20.0


def test_batched_numpy_matches_scalar_numpy():
    eta0 = np.array([[0.0, 0.0, np.pi / 2], [4.0, -3.0, 0.3]])
    V_c = np.array([[0.0, 0.5], [0.3, -0.2]])
    n = 100
    got = nr.simulate_batch(n, DT, eta0, V_c)
    for b in range(2):
        _, SE = nr.simulate(n, DT, nr.Scenario(eta0=tuple(eta0[b]), V_c=tuple(V_c[b])))
        np.testing.assert_allclose(got[b], np.mean(np.abs(SE[:, 1])), rtol=1e-12)


def test_numpy_remus100_step_reproduces_pvs_and_vcjax():
    """The plain-NumPy PVS step (``tests/reference/numpy_remus100.py``, the oracle of the REMUS 100 speed baseline ``benchmarks/perf/numpy_remus100.py``)
    replays the recorded PythonVehicleSimulator run to the CSV's digits, like vcjax does, and
    agrees with ``remus100.pvs_rollout`` to round-off (3000 steps, float64)."""
    import jax

    from tests.reference import numpy_remus100 as nrm
    from vcjax.vehicles import remus100 as rm

    ref = nrm.reference()
    p, args, x0, cmds = nrm.pvs_inputs()
    start = (nrm.columns(ref, k)[0] for k in (nrm.POSE, nrm.VEL, nrm.ACT))
    eta, nu, act = nrm.replay(
        nrm.numpy_params(p), *start, np.asarray(cmds), np.asarray(args.water.velocity[:2])
    )
    np.testing.assert_allclose(eta[:, :3], nrm.columns(ref, nrm.POSE)[:, :3], rtol=0, atol=1e-7)
    np.testing.assert_allclose(nu, nrm.columns(ref, nrm.VEL), rtol=0, atol=1e-8)
    np.testing.assert_allclose(act, nrm.columns(ref, nrm.ACT), rtol=0, atol=1e-6)
    rep = jax.jit(rm.pvs_rollout)(x0, cmds, args, nrm.DT)
    assert bool(np.all(np.asarray(rep.ok)))
    xs = rep.x
    np.testing.assert_allclose(eta, xs.eta, rtol=0, atol=1e-11)
    np.testing.assert_allclose(nu, xs.nu, rtol=0, atol=1e-12)
    np.testing.assert_allclose(act, xs.act, rtol=0, atol=1e-9)
