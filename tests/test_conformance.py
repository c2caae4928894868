"""Every registered vehicle x controller honours the loop contract (vcjax.loops): gains JSON
and gain-spec round trips, ``initial_from``, signal shapes, one finite step, and a gradient of a
short run equal to central finite differences; the registry refuses incomplete loop classes
and silent replacement of a vehicle (issue 24, item 5)."""

import dataclasses
import json
from pathlib import Path
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops, paths
from vcjax.config.scenario import import_module_file
from vcjax.rollout import RolloutConfig

ROOT = Path(__file__).resolve().parents[1]
import_module_file(ROOT / "examples" / "loops" / "puck.py")  # a user's loop, registered
import_module_file(ROOT / "examples" / "vehicles" / "skiff.py")  # a user's marine vehicle

BUILTIN = ("infante", "odin", "remus100", "arm")
CASES = [(v, c) for v in (*BUILTIN, "puck", "skiff") for c in loops.controllers(v)]
STEPS = 3
DT = 0.05


def _leaves(tree):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves(tree)]


def _same(a, b):
    la, lb = _leaves(a), _leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb, strict=True):
        np.testing.assert_array_equal(x, y)


def _loop(vehicle, controller):
    return loops.make_loop(vehicle, controller, smooth=True)


def _initial(loop):
    return {k: jnp.asarray(np.radians(v) if k.endswith("_deg") else v, float)
            for k, v in loop.initial_keys.items()}  # fmt: skip


@pytest.mark.parametrize("vehicle, controller", CASES)
def test_gains_json_and_gain_specs_round_trip(vehicle, controller):
    loop = _loop(vehicle, controller)
    if vehicle in BUILTIN:  # built-in loops hold their controllers as law objects
        assert isinstance(loop.law, loops.Law) and loop.controllers == tuple(type(loop).laws)
    g = loop.default_gains()
    _same(loop.gains_from_json(json.loads(json.dumps(loop.gains_to_json(g)))), g)
    specs = loop.gain_specs()
    assert specs and len({s.name for s in specs}) == len(specs)
    for s in specs:
        v = np.asarray(s.get(g))
        assert v.shape == (s.size,) and np.all(np.isfinite(v)), s.name
        _same(s.set(g, jnp.asarray(v)), g)  # writing back what was read changes nothing
        new = v * (1.0 + 0.1 * np.arange(1, s.size + 1))  # distinct factors: no index swap
        g2 = s.set(g, jnp.asarray(new))
        np.testing.assert_allclose(np.asarray(s.get(g2)), new, rtol=1e-15)
        for o in specs:  # the other groups are untouched
            if o.name != s.name:
                np.testing.assert_array_equal(np.asarray(o.get(g2)), np.asarray(o.get(g)))
        if s.bound is not None:
            assert np.all(np.asarray(s.bound(g)) > 0), s.name
    names = {s.name: s.size for s in specs}
    for a, i, b, j in loop.symmetric_pairs():
        assert i < names[a] and j < names[b]
    # the written file is what the reader reads: an unknown entry is refused, named
    with pytest.raises(ValueError, match="bogus"):
        loop.gains_from_json({**loop.gains_to_json(g), "bogus": 1.0})


@pytest.mark.parametrize("vehicle, controller", CASES)
def test_initial_from_uses_every_key(vehicle, controller):
    loop = _loop(vehicle, controller)
    vals = _initial(loop)
    eta0, nu0 = loop.initial_from(vals)
    sc = loops.make_scenario(loop)
    np.testing.assert_array_equal(np.asarray(eta0), np.asarray(sc.eta0))
    np.testing.assert_array_equal(np.asarray(nu0), np.asarray(sc.nu0))
    x0, _ = loop.initial_state(sc)
    assert np.shape(jax.tree_util.tree_leaves(x0)[0]) == np.shape(eta0)
    for k in vals:  # every key moves exactly one entry by the change
        e2, n2 = loop.initial_from(vals | {k: vals[k] + 0.25})
        d = np.concatenate([np.asarray(e2 - eta0), np.asarray(n2 - nu0)])
        assert np.count_nonzero(d) == 1 and np.isclose(d.sum(), 0.25), k


def _case(vehicle, controller):
    """(loop, gains, scenario, the first gain group, loss(a) of a run with its first entry
    shifted by a)."""
    loop = _loop(vehicle, controller)
    g = loop.default_gains()
    cur = (0.1, -0.2, 0.0) if loop.can_feel("current") else (0.0, 0.0, 0.0)
    sc = loops.make_scenario(loop, current=cur)
    spec = loop.gain_specs()[0]
    v0 = spec.get(g)
    cfg = RolloutConfig(num_steps=STEPS)

    def run(a):
        gains = spec.set(g, v0.at[0].add(a))
        traj = loops.simulate(loop, gains, sc, cfg, DT)
        sig = loop.signals(traj, sc)
        loss = jnp.sum(sig.cmd_ratio**2) + jnp.sum(sig.p_err**2) + jnp.sum(sig.u_err**2)
        return loss, (traj, sig)

    return loop, sc, v0, run


@pytest.mark.parametrize("vehicle, controller", CASES)
def test_one_step_is_finite_and_its_gradient_matches_finite_differences(vehicle, controller):
    """One control step and one plant evaluation at t = 0 (no scan: one small program,
    compiled once and evaluated at 0 and +-h, a fraction of the time of running its thousands
    of operations one by one): finite, the law's state rate shaped like its state, and the
    derivative of the step's output in the first tuned gain equal to central finite
    differences."""
    loop = _loop(vehicle, controller)
    g = loop.default_gains()
    cur = (0.1, -0.2, 0.0) if loop.can_feel("current") else (0.0, 0.0, 0.0)
    sc = loops.make_scenario(loop, current=cur, initial=_offset(loop))
    spec = loop.gain_specs()[0]
    v0 = spec.get(g)
    x0, z0 = loop.initial_state(sc)
    args = loop.plant_args(sc, sc.current, jnp.zeros(3))

    def step(a):
        ctrl = loop.ctrl_params(spec.set(g, v0.at[0].add(a)), sc)
        u, z_dot, _ = loop.control(0.0, x0, z0, ctrl)
        x_dot = loop.plant(0.0, x0, u, args)
        loss = sum(jnp.sum(v**2) for v in jax.tree_util.tree_leaves((u, z_dot, x_dot)))
        return loss, (u, z_dot, x_dot)

    value_and_grad = jax.jit(jax.value_and_grad(step, has_aux=True))
    (val, (u, z_dot, x_dot)), d = value_and_grad(jnp.asarray(0.0))
    assert all(np.all(np.isfinite(a)) for a in _leaves((u, z_dot, x_dot)))
    assert jax.tree_util.tree_structure(z_dot) == jax.tree_util.tree_structure(z0)
    h = 1e-6 * max(1.0, abs(float(v0[0])))
    loss = lambda a: float(value_and_grad(jnp.asarray(a))[0][0])
    fd = (loss(h) - loss(-h)) / (2 * h)
    assert np.isfinite(float(d))
    assert abs(float(d)) > 1e-6, (
        "the first tuned gain acts on the first step (else FD proves nothing)"
    )
    np.testing.assert_allclose(float(d), fd, rtol=1e-5, atol=1e-9 * max(1.0, float(val)))


def _offset(loop):
    """A start 0.3 m off the path: the path-error gains act from the first step, and the
    actuators stay inside their limits (a saturated fin or thruster has no derivative in the
    gains, and a derivative that is zero both ways proves nothing)."""
    return {"y": 0.3} if "y" in loop.initial_keys else {}


@pytest.mark.slow
@pytest.mark.parametrize("vehicle, controller", CASES)
def test_short_run_signals_and_gradient(vehicle, controller):
    """A run of a few steps: finite, signals of the documented shapes, and the reverse-mode
    gradient of a loss of its signals in the first tuned gain equal to central finite
    differences (compiles each loop's scan once: minutes for all of them)."""
    loop, sc, v0, run = _case(vehicle, controller)
    h = 1e-5 * max(1.0, abs(float(v0[0])))

    # one compiled function (reverse mode) evaluated at a = 0, +h, -h
    value_and_grad = jax.jit(jax.value_and_grad(run, has_aux=True))
    (v_0, (traj, sig)), g0 = value_and_grad(jnp.asarray(0.0))
    vals = [v_0] + [value_and_grad(jnp.asarray(a))[0][0] for a in (h, -h)]
    assert all(np.all(np.isfinite(a)) for a in _leaves(traj)), "a run of a few steps is finite"
    n = STEPS
    shapes = {
        "eps": (n, 2), "pos": (n, 3), "p_err": (n, 3), "u_err": (n,), "psi_err": (n,),
        "depth_err": (n,), "sat": (n,),
    }  # fmt: skip
    for k, shp in shapes.items():
        assert np.shape(getattr(sig, k)) == shp, k
    assert np.ndim(sig.cmd_ratio) == 2 and np.shape(sig.cmd_ratio)[0] == n
    # actuator magnitudes: per step, or per state (the final one included)
    assert sig.act and all(np.shape(a) in ((n,), (n + 1,)) for a in sig.act.values())
    fd = (float(vals[1]) - float(vals[2])) / (2 * h)
    assert np.isfinite(float(g0)) and float(g0) != 0.0
    np.testing.assert_allclose(float(g0), fd, rtol=2e-5, atol=1e-9 * abs(float(vals[0])))


# ------------------------------------------------------------------ the registry (issue 24.5)


def test_registering_a_loop_without_its_required_methods_names_them():
    @dataclasses.dataclass(frozen=True)
    class Half(loops.Loop):
        vehicle: ClassVar[str] = "half"
        controllers: ClassVar[tuple[str, ...]] = ("vcm",)

        @classmethod
        def default_path(cls):
            return paths.paper_line()

    with pytest.raises(ValueError, match="required methods") as err:
        loops.register(Half)
    msg = str(err.value)
    for name in ("plant", "control", "signals", "initial_from", "default_gains", "gain_specs"):
        assert f"'{name}'" in msg, name
    assert "'default_path'" not in msg and "half" not in loops.vehicles()

    @dataclasses.dataclass(frozen=True)
    class NoStep(loops.Law):
        def default_gains(self, loop):
            return None

        def gain_specs(self, loop):
            return ()

    with pytest.raises(ValueError, match=r"\['initial_state', 'params', 'step'\]"):
        loops.register_law("infante", "nostep", NoStep())
    assert "nostep" not in loops.controllers("infante")


def test_registering_a_taken_vehicle_name_is_refused_unless_replace():
    original = loops.loop_class("infante")

    @dataclasses.dataclass(frozen=True)
    class Impostor(original):
        vehicle: ClassVar[str] = "infante"

    with pytest.raises(ValueError, match="already registered") as err:
        loops.register(Impostor)
    msg = str(err.value)
    assert __name__ in msg and "vcjax.loops.infante.InfanteLoop" in msg and "replace=True" in msg
    assert loops.loop_class("infante") is original
    loops.register(original)  # registering the same class again is harmless
    try:
        assert loops.register(Impostor, replace=True) is Impostor
        assert loops.loop_class("infante") is Impostor
    finally:
        loops.register(original, replace=True)
    assert loops.loop_class("infante") is original
    with pytest.raises(ValueError, match="already has a controller 'vcm'"):
        loops.register_law("infante", "vcm", original.laws["vcm"])
