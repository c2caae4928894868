"""Edge cases of :mod:`vcjax.metrics` that the mutation run (``tools/mutation.py metrics``) found
untested: the boundaries of the checks, the first of several excursions, actuators named before
``e`` in the alphabet, and the ``diverged`` flag at and beyond its bound. Short made-up signals,
eager (a few milliseconds each)."""

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.loops import Signals
from vcjax.metrics import (
    first_excursion,
    path_bound,
    polyline_nearest,
    run_metrics,
    undefined_metrics,
)


def _signals(e, act=None):
    e = jnp.asarray(e, jnp.float64)
    n = e.shape[0]
    z = jnp.zeros(n)
    return Signals(
        eps=jnp.stack([z, e], axis=1),
        pos=jnp.zeros((n, 3)),
        p_err=jnp.zeros((n, 3)),
        u_err=z,
        psi_err=z,
        depth_err=z,
        cmd_ratio=jnp.zeros((n, 1)),
        sat=jnp.zeros(n, bool),
        act=act if act is not None else {"tau": jnp.ones(n)},
    )


def test_path_bound_takes_any_positive_bound():
    assert path_bound(1.0, 100.0, 0.5) == 0.5  # below 1 m is still a bound


def test_first_excursion_is_the_first_of_several():
    assert first_excursion([0.0, 5.0, 0.0, 6.0], 1.0) == 1


def test_one_step_run_has_metrics_and_no_step_is_refused():
    m = run_metrics(_signals([2.0]), jnp.ones(1, bool), 0.1, start=0.0)
    assert float(m["max_abs_e"]) == 2.0 and float(m["ss_abs_e"]) == 2.0
    with pytest.raises(ValueError, match="at least one step"):
        run_metrics(_signals(jnp.zeros(0)), jnp.ones(0, bool), 0.1)


def test_every_actuator_gets_its_max_whatever_its_name():
    # "delta_r" and "X" sort before "e": the one "max_abs_" key that is not an actuator
    n = 4
    act = {"X": jnp.full(n, 3.0), "delta_r": jnp.full(n, 0.2), "tau": jnp.full(n, 7.0)}
    m = run_metrics(_signals(jnp.ones(n), act), jnp.ones(n, bool), 0.1)
    assert {k: float(m[f"max_abs_{k}"]) for k in act} == {"X": 3.0, "delta_r": 0.2, "tau": 7.0}


def test_diverged_at_the_bound_and_when_nonfinite_beyond_it():
    e = jnp.array([0.0, 1.0, 2.0, 1.0])
    ok = jnp.ones(4, bool)
    at = run_metrics(_signals(e), ok, 0.1, diverge_e=2.0)
    assert not bool(at["diverged"])  # |e| <= bound: not diverged
    assert bool(run_metrics(_signals(e), ok, 0.1, diverge_e=1.5)["diverged"])
    bad = run_metrics(_signals(e.at[3].set(np.nan)), ok.at[3].set(False), 0.1, diverge_e=1.5)
    assert bool(bad["nonfinite"]) and bool(bad["diverged"])  # both reasons at once


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"finite": jnp.ones(4, bool)}, "finite: expected shape"),  # one flag too many
        ({"start": -0.5}, r"fraction in \[0, 1\)"),
        ({"start": 1.5}, r"fraction in \[0, 1\)"),
    ],
)
def test_run_inputs_refused_by_their_own_check(kwargs, match):
    args = {"finite": jnp.ones(3, bool), "start": 0.5} | kwargs
    with pytest.raises(ValueError, match=match):
        run_metrics(_signals(jnp.ones(3)), args["finite"], 0.1, start=args["start"])


def test_undefined_metrics_reads_past_a_flag():
    got = undefined_metrics({"healthy": True, "x": float("nan"), "y": 1.0, "z": None})
    assert set(got) == {"x", "z"}


def test_polyline_nearest_parameter_of_a_path_not_starting_at_zero():
    ws = np.array([10.0, 11.0, 12.0])  # p(w) along north, 1 m per unit of w from w = 10
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    _, w, _, _ = polyline_nearest(np.array([[1.5, 1.0, 0.0]]), pts, ws)
    np.testing.assert_allclose(w, [11.5], rtol=1e-14)


def test_polyline_nearest_on_segments_of_other_lengths_and_directions():
    # w = 10, 12, ..., 18 (dw = 2) at the vertices of legs 3 m north, 4 m east, 3 m south,
    # 5 m down, and a point before the start: the nearest point's parameter, distance and its leg's unit tangent
    ws = np.arange(10.0, 19.0, 2.0)
    pts = np.array([[0, 0, 0], [3, 0, 0], [3, 4, 0], [0, 4, 0], [0, 4, 5]], float)
    pos = np.array([[1.5, -1, 0], [4, 2, 0], [1, 5, 0], [1, 4, 3], [-1, 0, 0]], float)
    dist, w, _, tangent = polyline_nearest(pos, pts, ws)
    np.testing.assert_allclose(dist, [1.0, 1.0, 1.0, 1.0, 1.0], rtol=1e-14)
    np.testing.assert_allclose(w, [11.0, 13.0, 14.0 + 4.0 / 3.0, 17.2, 10.0], rtol=1e-14)
    tangents = [[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, 0, 1], [1, 0, 0]]  # the first at the start
    np.testing.assert_allclose(tangent, tangents, atol=1e-14)


def test_polyline_nearest_with_a_repeated_vertex_stays_finite():
    ws = np.array([0.0, 1.0, 2.0])  # the path stalls over the first step: a zero-length leg
    pts = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0]], float)
    out = polyline_nearest(np.array([[-1.0, 0, 0], [0.5, 1.0, 0]]), pts, ws)
    assert all(np.isfinite(np.asarray(x)).all() for x in out)
    np.testing.assert_allclose(out[1], [0.0, 1.5], atol=1e-14)
