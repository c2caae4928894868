"""Parameters and gains by name (vcjax.loops.params, .pm): dotted names, lookup and replacement,
the one gains-JSON reader and writer, GainSpec get / set / bound, and the Routh–Hurwitz bound of
the integral gains against the roots of the characteristic polynomial. Eager or tiny programs."""

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops
from vcjax.control.vcm import pm_gains
from vcjax.loops.pm import PM_PAIRS, pm_gain_specs


class Body(NamedTuple):
    W: Any
    M_A: Any


class Craft(NamedTuple):
    mass: Any
    body: Body
    limits: Any


def craft():
    return Craft(
        mass=jnp.asarray(30.0),
        body=Body(W=jnp.asarray(294.0), M_A=jnp.eye(2)),
        limits=jnp.asarray([1.0, 2.0, 3.0]),
    )


class Inner(NamedTuple):
    k_p: Any  # ()
    k: Any  # (3,)


class Gains(NamedTuple):
    inner: Inner
    sigma: Any  # ()


def gains():
    return Gains(inner=Inner(k_p=jnp.asarray(2.0), k=jnp.asarray([1.0, 2.0, 3.0])), sigma=0.5)


def test_param_names_are_dotted_for_nesting_and_reach_every_field():
    p = craft()
    assert loops.param_names(p) == ("mass", "body.W", "body.M_A", "limits")
    assert float(loops.get_param(p, "body.W")) == 294.0
    np.testing.assert_array_equal(loops.get_param(p, "body.M_A"), np.eye(2))
    with pytest.raises(AttributeError):
        loops.get_param(p, "body.D")


def test_replace_params_changes_only_the_named_fields_and_traces():
    p = craft()
    q = loops.replace_params(p, {"mass": 31.0, "body.W": 300.0})
    assert float(q.mass) == 31.0 and float(q.body.W) == 300.0
    assert q.body.M_A is p.body.M_A and q.limits is p.limits and float(p.mass) == 30.0

    @jax.jit
    def scaled(s):  # traced values: d(mass * W) / ds at s = 1
        r = loops.replace_params(p, {"mass": s * p.mass, "body.W": s * p.body.W})
        return r.mass * r.body.W

    assert float(jax.grad(scaled)(1.0)) == pytest.approx(2 * 30.0 * 294.0, rel=1e-14)


def test_gains_json_round_trip_keeps_values_shapes_and_dtypes():
    g = gains()._replace(sigma=jnp.asarray(0.5, jnp.float32))
    d = loops.gains_to_json(g)
    assert d == {"inner": {"k_p": 2.0, "k": [1.0, 2.0, 3.0]}, "sigma": 0.5}
    back = loops.gains_from_json(d, g)
    for a, b in zip(jax.tree_util.tree_leaves(back), jax.tree_util.tree_leaves(g), strict=True):
        assert a.dtype == jnp.asarray(b).dtype and a.shape == jnp.shape(b)
        np.testing.assert_array_equal(a, b)
    # missing entries keep the default; integers are read as floats
    part = loops.gains_from_json({"inner": {"k": [4, 5, 6]}}, g)
    np.testing.assert_array_equal(part.inner.k, [4.0, 5.0, 6.0])
    assert part.inner.k.dtype == g.inner.k.dtype and float(part.inner.k_p) == 2.0


@pytest.mark.parametrize(
    "d, message",
    [
        ([1, 2], r"gains file: expected an object, got list"),
        ({"tau": 1.0}, r"unknown sections \['tau'\]; expected \['inner', 'sigma'\]"),
        ({"inner": {"kd": 1.0}}, r"gains file: inner: unknown entries \['kd'\]"),
        ({"inner": 3.0}, r"section 'inner' must be an object of gains, got float"),
        ({"inner": {"k": [1.0, 2.0]}}, r"inner: k: expected shape \(3,\), got \(2,\)"),
        ({"sigma": "fast"}, r"sigma: expected a numeric array, got 'fast'"),
        ({"sigma": float("nan")}, r"sigma: not finite"),
        ({"inner": {"k": [1.0, float("inf"), 2.0]}}, r"inner: k: not finite"),
    ],
)
def test_gains_json_reader_names_the_bad_entry(d, message):
    with pytest.raises(ValueError, match=message):
        loops.gains_from_json(d, gains())


def test_gains_json_reader_runs_the_laws_checks():
    def positive(g):
        if float(g.sigma) <= 0:
            raise ValueError("sigma: must be > 0")
        return g

    def typed(g):
        raise TypeError("pm_gains() got an unexpected keyword argument 'x'")

    with pytest.raises(ValueError, match="sigma: must be > 0"):
        loops.gains_from_json({"sigma": -1.0}, gains(), validate=positive)
    with pytest.raises(ValueError, match=r"my file: pm_gains\(\) got an unexpected keyword"):
        loops.gains_from_json({}, gains(), where="my file", validate=typed)


def test_gain_spec_reads_and_writes_a_scalar_as_one_entry():
    spec = loops.gain_spec("k_p", "inner.k_p")
    assert spec.name == "k_p" and spec.size == 1 and spec.bound is None
    g = gains()
    np.testing.assert_array_equal(spec.get(g), [2.0])  # () read as (1,)
    h = spec.set(g, jnp.asarray([7.0]))
    assert jnp.shape(h.inner.k_p) == () and float(h.inner.k_p) == 7.0  # written back as ()
    np.testing.assert_array_equal(h.inner.k, g.inner.k)


def test_gain_spec_of_a_slice_and_of_a_whole_vector():
    tail = loops.gain_spec("k_tail", "inner.k", index=slice(1, 3))
    assert tail.size == 2
    g = gains()
    np.testing.assert_array_equal(tail.get(g), [2.0, 3.0])
    np.testing.assert_array_equal(tail.set(g, jnp.asarray([8.0, 9.0])).inner.k, [1.0, 8.0, 9.0])
    whole = loops.gain_spec("k", "inner.k", 3)
    np.testing.assert_array_equal(whole.set(g, jnp.asarray([4.0, 5.0, 6.0])).inner.k, [4, 5, 6])
    # set is pure and traceable: d sum(k) / d value through a jitted set
    f = jax.jit(lambda v: jnp.sum(whole.set(g, v).inner.k * jnp.arange(3.0)))
    np.testing.assert_array_equal(jax.grad(f)(jnp.ones(3)), [0.0, 1.0, 2.0])


def test_routh_hurwitz_bound_separates_stable_from_unstable_integral_gains():
    """Each error row with integral action (41) has the characteristic polynomial
    s^3 + (p_G + p_Phi) s^2 + p_G p_Phi s + k_int; Routh–Hurwitz: stable iff k_int below
    (p_G + p_Phi) p_G p_Phi. Checked against the polynomial's roots."""
    P_G = jnp.asarray([0.4, 0.3, 0.7])
    P_Phi = jnp.asarray([1.0, 1.0, 1.0, 0.8, 1.5])
    bound = np.asarray(loops.rh_bound(P_G, P_Phi))
    np.testing.assert_allclose(bound, [(0.3 + 0.8) * 0.3 * 0.8, (0.7 + 1.5) * 0.7 * 1.5])
    for row, (pg, pphi) in enumerate(((0.3, 0.8), (0.7, 1.5))):
        for factor, stable in ((0.98, True), (1.02, False)):
            roots = np.roots([1.0, pg + pphi, pg * pphi, factor * bound[row]])
            assert (np.max(roots.real) < 0) == stable, (row, factor, roots)


def test_pm_gain_specs_follow_the_law_options_and_bound_p_int():
    assert [s.name for s in pm_gain_specs("vcm", integral=False, ilos=False)] == [
        "P_G",
        "P_Phi",
        "Delta",
        "sigma",
    ]
    specs = {s.name: s for s in pm_gain_specs("vcm", integral=True, ilos=True)}
    assert list(specs) == ["P_G", "P_Phi", "Delta", "sigma", "P_int", "sigma_i"]
    g = loops.infante_gains()
    pm = g.vcm
    np.testing.assert_array_equal(specs["P_G"].get(g), pm.P_G)
    np.testing.assert_array_equal(specs["P_int"].bound(g), loops.rh_bound(pm.P_G, pm.P_Phi))
    # the bound moves with the other gains: double P_G, and the bound follows
    g2 = specs["P_G"].set(g, 2 * pm.P_G)
    assert np.all(np.asarray(specs["P_int"].bound(g2)) > np.asarray(specs["P_int"].bound(g)))
    assert PM_PAIRS == (("P_G", 1, "P_Phi", 3), ("P_G", 2, "P_Phi", 4))
    assert float(specs["sigma_i"].get(g)[0]) == float(pm_gains().sigma_i)
