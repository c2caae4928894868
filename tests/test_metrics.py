"""Every metric of :func:`vcjax.metrics.run_metrics` against a value computed by hand.

Five steps of made-up signals with numbers chosen so that each metric has a short closed form;
the expected values are written out here as numbers (worked in the comments), not recomputed
with the formulas under test. With ``start = 0.6`` the steady-state window is steps 3 and 4.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.loops import Signals
from vcjax.metrics import first_true, metric_names, polyline_nearest, run_metrics, window_start

DT = 0.5
#           step:   0     1     2     3      4
E = np.array([3.0, -2.0, 1.0, -0.5, 0.25])  # cross-track e [m]
S = np.array([1.0, 1.0, -1.0, 0.2, -0.4])  # along-track s [m]
U_ERR = np.array([0.5, -0.5, 0.1, -0.3, 0.1])  # speed error [m/s]
P_ERR = np.array(
    [[10.0, 0, 0], [0, 5.0, 0], [1.0, 1.0, 1.0], [0.3, 0.4, 0.0], [0.0, 0.0, -1.2]]
)  # distance 10, 5, 1.73, 0.5, 1.2
DEPTH = np.array([0.0, 0.0, 0.0, 0.6, -0.8])  # depth error [m]
SAT = np.array([True, False, True, False, False])
TAU = np.array([1.0, 7.0, 3.0, 2.0, 0.5])  # an actuator's magnitude per step


def signals(e=E):
    n = len(e)
    z = jnp.zeros(n)
    return Signals(
        eps=jnp.stack([jnp.asarray(S), jnp.asarray(e)], axis=1),
        pos=jnp.zeros((n, 3)),
        p_err=jnp.asarray(P_ERR),
        u_err=jnp.asarray(U_ERR),
        psi_err=z,
        depth_err=jnp.asarray(DEPTH),
        cmd_ratio=jnp.zeros((n, 1)),
        sat=jnp.asarray(SAT),
        act={"tau": jnp.asarray(TAU)},
    )


EXPECTED = {
    "ss_abs_e": 0.375,  # (0.5 + 0.25) / 2
    "ss_abs_s": 0.3,  # (0.2 + 0.4) / 2
    "ss_abs_u_err": 0.2,  # (0.3 + 0.1) / 2
    "iae_e": 3.375,  # (3 + 2 + 1 + 0.5 + 0.25) * 0.5 s
    "max_abs_e": 3.0,  # whole run
    "max_abs_tau": 7.0,  # whole run
    "rms_along_track_s": math.sqrt(0.1),  # (0.04 + 0.16) / 2
    "rms_cross_track_e": math.sqrt(0.15625),  # (0.25 + 0.0625) / 2
    "rms_dist_3d": math.sqrt(0.845),  # (0.25 + 1.44) / 2
    "max_dist_3d": 1.2,  # window only: the 10 m of step 0 is outside it
    "rms_depth_err": math.sqrt(0.5),  # (0.36 + 0.64) / 2
    "sat_fraction": 0.4,  # 2 of 5 steps, whole run
}


def test_every_metric_against_a_hand_computation():
    assert window_start(5, 0.6) == 3
    m = run_metrics(signals(), jnp.ones(5, bool), DT, start=0.6)
    assert set(EXPECTED) == set(metric_names(["tau"])), "a metric was added: compute it by hand"
    for name, value in EXPECTED.items():
        np.testing.assert_allclose(float(m[name]), value, rtol=1e-12, err_msg=name)
    assert not bool(m["nonfinite"]) and not bool(m["diverged"])


def test_metric_names_order():
    """The column order of sweep tables and metrics files: the run-wide error metrics, one
    ``max_abs_`` per actuator in the loop's order, then the windowed RMS and distance metrics."""
    assert metric_names(["tau_u", "rudder_deg"]) == (
        "ss_abs_e",
        "ss_abs_s",
        "ss_abs_u_err",
        "iae_e",
        "max_abs_e",
        "max_abs_tau_u",
        "max_abs_rudder_deg",
        "rms_along_track_s",
        "rms_cross_track_e",
        "rms_dist_3d",
        "max_dist_3d",
        "rms_depth_err",
        "sat_fraction",
    )


def test_health_flags():
    finite = jnp.array([True, True, True, False, True])
    m = run_metrics(signals(), finite, DT, start=0.6)
    assert bool(m["nonfinite"]) and bool(m["diverged"])
    # a cross-track bound below the largest |e| (3 m) flags divergence, one above it does not
    assert bool(run_metrics(signals(), jnp.ones(5, bool), DT, 0.6, diverge_e=2.5)["diverged"])
    assert not bool(run_metrics(signals(), jnp.ones(5, bool), DT, 0.6, diverge_e=3.5)["diverged"])
    # NaN in the error counts as diverged even if the rollout said finite
    e = E.copy()
    e[1] = np.nan
    assert bool(run_metrics(signals(e), jnp.ones(5, bool), DT, 0.6, diverge_e=10.0)["diverged"])


@pytest.mark.parametrize("start, k0", [(0.8, 4), (0.0, 0), (0.2, 1)])
def test_window_start_moves_the_window(start, k0):
    assert window_start(5, start) == k0
    m = run_metrics(signals(), jnp.ones(5, bool), DT, start=start)
    np.testing.assert_allclose(float(m["ss_abs_e"]), np.mean(np.abs(E[k0:])), rtol=1e-12)


def test_extras_are_computed_in_the_same_call_on_the_window():
    # an experiment's extra sees the signals and the window mask (steps 3 and 4 at start 0.6)
    extras = {
        "last_e": lambda sig, win: sig.eps[-1, 1],
        "window_steps": lambda sig, win: jnp.sum(win.astype(sig.eps.dtype)),
        "peak_tau_in_window": lambda sig, win: jnp.max(jnp.where(win, sig.act["tau"], 0.0)),
    }
    m = run_metrics(signals(), jnp.ones(5, bool), DT, start=0.6, extras=extras)
    assert float(m["last_e"]) == 0.25
    assert float(m["window_steps"]) == 2.0
    assert float(m["peak_tau_in_window"]) == 2.0  # TAU[3], TAU[4] = 2, 0.5
    np.testing.assert_allclose(float(m["ss_abs_e"]), EXPECTED["ss_abs_e"], rtol=1e-12)
    with pytest.raises(ValueError, match=r"extras: \['ss_abs_e'\] are generic metrics"):
        run_metrics(signals(), jnp.ones(5, bool), DT, extras={"ss_abs_e": extras["last_e"]})


def test_first_true():
    assert int(first_true(jnp.array([False, False, True, True]))) == 2
    assert int(first_true(jnp.array([True, False]))) == 0
    assert int(first_true(jnp.zeros(4, bool))) == -1


def test_polyline_nearest_against_hand_computation():
    # an L-shaped polyline sampled at w = 0, 1, 2, 3, 4: (0,0,0) -> (2,0,0) -> (2,2,0)
    ws = np.arange(5.0)
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [2, 2, 0]], float)
    pos = np.array(
        [
            [0.5, 1.0, 0.0],  # above the first leg: nearest (0.5, 0, 0), w = 0.5, distance 1
            [3.0, 1.5, 2.0],  # beside the second leg: nearest (2, 1.5, 0), w = 3.5
            [3.0, -1.0, 0.0],  # outside the corner: nearest the vertex (2, 0, 0), w = 2
            [-1.0, 0.0, 0.0],  # before the start: nearest (0, 0, 0), w = 0
        ]
    )
    dist, w, off, tangent = polyline_nearest(pos, pts, ws, batch=2)
    np.testing.assert_allclose(dist, [1.0, math.sqrt(5.0), math.sqrt(2.0), 1.0], rtol=1e-14)
    np.testing.assert_allclose(w, [0.5, 3.5, 2.0, 0.0], atol=1e-14)
    np.testing.assert_allclose(off, [[0, 1, 0], [1, 0, 2], [1, -1, 0], [-1, 0, 0]], atol=1e-14)
    # the tangent of the segment the nearest parameter falls in; at the vertex w = 2 the one
    # before it (searchsorted left), at the start the first
    np.testing.assert_allclose(tangent, [[1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 0, 0]], atol=1e-14)
