"""Tests that kill the survivors of a whole mutation run of the tuner's optimiser
(``tuning.optim``, docs/development/testing.md, "Mutation testing"), after those written ahead of
it (``tests/test_tuning_power_optim.py``).

The expected values come from elsewhere: Adam's update written out in numpy, the guard's
documented rules (a step whose loss, gradient or update is not finite is rejected; the best
parameters are the lowest loss seen at an accepted step's input, or the final iterate when
lower), the same L-BFGS step run without the program store, stand-ins for the store and the
device mesh that record what they are given.
"""

from __future__ import annotations

import dataclasses
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_tuning_power_optim import _adam_numpy  # Adam written out in numpy


def _bowl(th, c):
    """() a quadratic bowl around ``c`` (2,)."""
    return 0.5 * jnp.sum((th - c) ** 2)


# ------------------------------------------------------------------ the optimisers' defaults


def test_make_optimizer_adam_defaults_to_its_documented_rate():
    """Kills: ``make_optimizer``'s own default learning rate (0.05, the ``[optimizer]``
    section's): Adam's first update is ``-lr g / (|g| + eps)`` per entry; the names compared
    exactly (one that sorts before ``"adam"`` refused too)."""
    from tuning.optim import make_optimizer

    opt = make_optimizer("adam")
    g = jnp.asarray([3.0, -4.0])
    with jax.numpy_dtype_promotion("standard"):  # optax's bias correction, as in the tuner
        upd, _ = opt.update(g, opt.init(jnp.zeros(2)))
    np.testing.assert_allclose(upd, -0.05 * np.array([3.0, -4.0]) / (np.array([3, 4]) + 1e-8))
    for wrong in ("Adam", "LBFGS", "adagrad", "sgd"):  # names are exact, lower case
        with pytest.raises(ValueError, match=wrong):
            make_optimizer(wrong)


def test_tuner_options_run_fifty_steps_by_default_and_report_progress():
    """Kills: ``TunerOptions.steps``' default (50), the progress hook's arguments (the steps
    done, the steps planned, the step's record). Adam far from the bowl's centre: no stop
    before the last step (Adam moves at most about ``lr`` per step)."""
    from tuning.optim import run_gradient_tuner

    seen = []
    res = run_gradient_tuner(
        _bowl,
        jnp.zeros(2),
        (jnp.asarray([10.0, -10.0]),),
        optimizer="adam",
        progress=lambda k, n, rec: seen.append((k, n, rec)),
    )
    assert len(res.history) == 50 and res.reason == "steps"
    assert [(k, n) for k, n, _ in seen] == [(k + 1, 50) for k in range(50)]
    assert all(rec is h for (_, _, rec), h in zip(seen, res.history, strict=True))


# ------------------------------------------------------------------ the guard


def test_a_step_with_an_infinite_loss_and_a_finite_gradient_is_rejected():
    """Kills: the guard's ``isfinite(loss) & finite(gradient)`` (``|``, ``^``): a loss of +inf
    whose gradient is finite (0 where the loss is the constant inf) is rejected like a NaN
    one, the step's input kept; the next step (scale 1/2) is Adam's from there."""
    from tuning.optim import run_gradient_tuner

    def loss(th, c):  # +inf right of th[0] = 0.5, with a zero gradient there
        return jnp.where(th[0] > 0.5, jnp.inf, _bowl(th, c))

    res = run_gradient_tuner(
        loss, jnp.asarray([0.6, 0.0]), (jnp.ones(2),), optimizer="adam", steps=1
    )
    h = res.history[0]
    assert not h["ok"] and h["loss"] is None and h["grad_norm"] == 0.0
    assert h["update_norm"] == 0.0 and res.n_bad == 1
    np.testing.assert_array_equal(res.theta, [0.6, 0.0])


def test_equal_losses_keep_the_first_parameters_that_reached_them():
    """Kills: the best-so-far test ``loss < best`` (``<=``) and the final iterate's
    ``final < best`` (``<=``): a loss exactly 1 everywhere (its gradient ``g`` nonzero, so
    Adam moves) keeps the start as the best parameters, as documented (the lowest loss seen;
    the final iterate only when lower)."""
    from tuning.optim import run_gradient_tuner

    def flat(th, g):  # value 1 exactly (x - x = 0), gradient g
        x = th @ g
        return 1.0 + (x - jax.lax.stop_gradient(x))

    res = run_gradient_tuner(
        flat, jnp.zeros(2), (jnp.asarray([1.0, -2.0]),), optimizer="adam", steps=3
    )
    assert [r["loss"] for r in res.history] == [1.0, 1.0, 1.0]
    assert all(r["update_norm"] > 0.0 for r in res.history)
    np.testing.assert_array_equal(res.theta, [0.0, 0.0])
    assert res.loss == 1.0


# ------------------------------------------------------------------ placement


class _Mesh:
    def __init__(self, size):
        self.size = size


class _Sharded:
    """A stand-in leaf placed on a mesh of ``size`` devices."""

    def __init__(self, size):
        self.sharding = types.SimpleNamespace(mesh=_Mesh(size))


def test_replicate_like_places_on_the_first_mesh_of_several_devices(monkeypatch):
    """Kills: ``mesh.size > 1`` (a one-device mesh leaves the trees alone; a two-device one,
    the first such leaf's, replicates every tree on it) and the loop over the leaves."""
    from tuning import optim
    from vcjax.runtime import distributed

    monkeypatch.setattr(distributed, "replicate", lambda t, mesh: ("replicated", t, mesh))
    one, two, three = _Sharded(1), _Sharded(2), _Sharded(3)
    assert optim.replicate_like((np.zeros(2), one), "a", "b") == ("a", "b")
    got = optim.replicate_like((np.zeros(2), one, [two, three]), "a", "b")
    assert got == (("replicated", "a", two.sharding.mesh), ("replicated", "b", two.sharding.mesh))
    assert optim.replicate_like((), "a") == ("a",)


# ------------------------------------------------------------------ the L-BFGS step's programs


def _lbfgs(program_static=None):
    from tuning.optim import make_optimizer, make_step

    opt = make_optimizer("lbfgs", memory_size=3, max_linesearch_steps=4)
    return opt, make_step(_bowl, opt, "lbfgs", "reverse", program_static=program_static)


def _store(monkeypatch, tmp_path, on=True):
    """The program store on (a folder) or off, ``programs.build`` a recording stand-in that
    compiles with ``jax.jit``; returns (builds, calls of the built program)."""
    from vcjax.runtime import programs

    built, calls = [], []

    def build(name, fn, static, args):
        built.append((name, static, programs.argument_spec(args)))
        jitted = jax.jit(lambda *a: fn(*a))  # (not jax.jit(fn): that shares fn's cache)

        def call(*a):
            calls.append(np.asarray(a[0]))
            return jitted(*a)

        return call, {}

    monkeypatch.setattr(programs, "store_dir", lambda: tmp_path if on else None)
    monkeypatch.setattr(programs, "build", build)
    return built, calls


def test_the_lbfgs_step_takes_its_value_and_grad_from_the_store_once(monkeypatch, tmp_path):
    """Kills: the store's use (only with the store on and a ``program_static``; the key's static
    part ``(program_static, grad_mode)``), one build at the first call, the stored program run
    for arguments of its spec and the jitted one for others; the same step as without it."""
    from tuning.optim import init_state

    th, c = jnp.zeros(2), jnp.asarray([1.0, -2.0])
    opt, plain = _lbfgs()
    ref = plain(th, init_state(opt, th), jnp.asarray(1.0), (c,))

    built, calls = _store(monkeypatch, tmp_path)
    _, step = _lbfgs(program_static="cfg")
    th1, _, info = step(th, init_state(opt, th), jnp.asarray(1.0), (c,))
    from vcjax.runtime import programs

    assert built == [
        ("tune:value_and_grad", ("cfg", "reverse"), programs.argument_spec((th, (c,))))
    ]
    assert len(calls) == int(info.evals) >= 2  # every evaluation: the stored program
    np.testing.assert_array_equal(calls[0], th)
    np.testing.assert_allclose(th1, ref[0], rtol=1e-15)
    assert float(info.loss) == float(ref[2].loss) == 2.5
    assert step._vg._cache_size() == 0 and step._cache_size() == 1
    v, g = step.value_and_grad(jnp.zeros(3), (jnp.ones(3),))  # another spec: the jitted one
    assert float(v) == 1.5 and np.array_equal(g, -np.ones(3))
    assert len(built) == 1 and len(calls) == int(info.evals) and step._vg._cache_size() == 1
    assert step._cache_size() == 2
    v, g = step.value_and_grad(jnp.zeros(1), (jnp.ones(1),))  # a spec that sorts before
    assert float(v) == 0.5 and np.array_equal(g, [-1.0]) and len(calls) == int(info.evals)

    _, nostatic = _lbfgs()  # the store on, no program_static: never stored
    nostatic(th, init_state(opt, th), jnp.asarray(1.0), (c,))
    assert len(built) == 1 and nostatic._vg._cache_size() == 1 and nostatic._cache_size() == 1

    built_off, _ = _store(monkeypatch, tmp_path, on=False)  # the store off: never stored
    _, off = _lbfgs(program_static="cfg")
    off(th, init_state(opt, th), jnp.asarray(1.0), (c,))
    assert built_off == [] and off._cache_size() == 1


def test_prebuild_compiles_the_value_and_grad_the_step_then_runs(monkeypatch, tmp_path):
    """Kills: ``prebuild`` without the store (a compiled program for the arguments' spec, run by
    the step instead of tracing its own) and with it (built from the store, once, with the
    step's static key), and ``_cache_size`` counting it."""
    from tuning.optim import init_state

    th, c = jnp.zeros(2), jnp.asarray([1.0, -2.0])
    built, calls = _store(monkeypatch, tmp_path, on=False)
    opt, step = _lbfgs(program_static="cfg")
    step.prebuild(th, (c,))
    assert built == [] and step._cache_size() == 1
    _, _, info = step(th, init_state(opt, th), jnp.asarray(1.0), (c,))
    assert step._vg._cache_size() == 0 and step._cache_size() == 1 and float(info.loss) == 2.5

    built, calls = _store(monkeypatch, tmp_path)
    _, stored = _lbfgs(program_static="cfg")
    stored.prebuild(th, (c,))
    assert [b[:2] for b in built] == [("tune:value_and_grad", ("cfg", "reverse"))]
    _, _, info = stored(th, init_state(opt, th), jnp.asarray(1.0), (c,))
    assert len(built) == 1 and len(calls) == int(info.evals) and stored._vg._cache_size() == 0

    built, calls = _store(monkeypatch, tmp_path)
    _, nostatic = _lbfgs()  # the store on, no program_static: compiled, not stored
    nostatic.prebuild(th, (c,))
    assert built == [] and nostatic._cache_size() == 1


# ------------------------------------------------------------------ the loop's bookkeeping


def _scripted(script, seen):
    """A stand-in step (``run_gradient_tuner``'s ``step_fn``): its k-th call reports
    ``script[k] = (loss, ok, update_norm)``, moves an accepted input by (1, 0) and returns the
    call's index as the optimiser state; ``seen`` gets each call's (input, state, scale, args)."""
    from tuning.optim import StepInfo

    calls = iter(range(len(script)))

    def step(theta, state, scale, args):
        k = next(calls)
        loss, ok, unorm = script[k]
        seen.append((np.asarray(theta).tolist(), state, float(scale), args))
        new = theta + jnp.asarray([1.0, 0.0]) if ok else theta
        info = StepInfo(
            jnp.asarray(loss), jnp.asarray(7.0), jnp.asarray(ok), jnp.asarray(2, jnp.int32), unorm
        )
        return new, k, info

    return step


def test_the_loop_reverts_halves_and_counts_stalls_by_its_rules():
    """Kills (``_Loop``): a rejected step's revert to the last accepted step's input and state,
    the step halved at each rejection and kept after an accepted one, the stall count (three
    accepted zero updates in a row: a rejected step or a nonzero update starts it again), the
    evaluation counts, the best input (the lowest loss at an accepted step's input), the count
    of consecutive rejections (reset by an accepted step) that aborts."""
    from tuning.optim import run_gradient_tuner

    nan = float("nan")
    script = [
        (5.0, True, 0.0),  # 0: from (0, 0), stall 1
        (4.0, True, 0.0),  # 1: from (1, 0), stall 2
        (3.0, True, 0.5),  # 2: from (2, 0), moves: stall count back to 0
        (2.0, True, 0.0),  # 3: from (3, 0), stall 1
        (nan, False, 0.0),  # 4: from (4, 0): rejected, back to (3, 0) and state 2, scale 1/2
        (2.5, True, 0.0),  # 5: from (3, 0), scale 1/2, stall 1 (the rejection reset it)
        (nan, False, 0.0),  # 6: from (4, 0): rejected again, back to (3, 0), scale 1/4
        (2.5, True, 0.0),  # 7: from (3, 0), stall 1
        (1.0, True, 0.0),  # 8: from (4, 0), stall 2
    ]

    def run(scripted, steps=None, **kw):  # the loss is 9 everywhere: the script moves
        seen = []
        res = run_gradient_tuner(
            lambda th, a: jnp.sum(th) * 0.0 + a,
            jnp.zeros(2),
            (jnp.asarray(9.0),),
            optimizer="adam",
            steps=len(scripted) if steps is None else steps,
            step_fn=_scripted(scripted, seen),
            **kw,
        )
        return res, seen

    # two rejections, not in a row: no abort
    res, seen = run(script, grad_tol=0.0, max_bad_steps=2)
    assert [s[0][0] for s in seen] == [0, 1, 2, 3, 4, 3, 4, 3, 4]
    assert [s[1] for s in seen[1:]] == [0, 1, 2, 3, 2, 5, 2, 7]
    assert [s[2] for s in seen] == [1, 1, 1, 1, 1, 0.5, 0.5, 0.25, 0.25]
    assert res.reason == "steps" and res.n_bad == 2 and not res.aborted
    assert res.evals == 18 and [r["cum_evals"] for r in res.history] == list(range(2, 20, 2))
    assert [r["grad_norm"] for r in res.history] == [7.0] * 9
    np.testing.assert_array_equal(res.theta, [4.0, 0.0])  # step 8's input, loss 1
    assert res.loss == 1.0  # the final iterate's loss (9, from the loss function) is higher

    # a third zero update in a row: stalled there (the last step)
    res, _ = run(script[:3] + [(2.0, True, 0.0)] * 3, grad_tol=0.0)
    assert res.reason == "stalled" and len(res.history) == 6

    # two rejections in a row after an accepted step: aborted there
    res, _ = run([script[0], script[4], script[4], script[0]], steps=9, max_bad_steps=2)
    assert res.reason == "aborted: 2 consecutive non-finite steps" and len(res.history) == 3
    np.testing.assert_array_equal(res.theta, [0.0, 0.0])
    assert res.loss == 5.0 and res.aborted


def test_a_refresh_restarts_the_best_and_the_step_size_and_keeps_adams_state():
    """Kills: ``TunerHooks.refresh``'s restart (the best parameters and loss those of the new
    arguments from there on, the halved step back to 1, the new arguments used), Adam's state
    carried across it (only L-BFGS restarts its memory), the final iterate taken when lower."""
    from tuning.optim import TunerHooks, run_gradient_tuner

    nan = float("nan")
    script = [(1.0, True, 0.5), (nan, False, 0.0), (2.0, True, 0.5)]
    script += [(5.0, True, 0.5), (6.0, True, 0.5)]  # after the refresh
    seen, asked = [], []

    def refresh(k, theta, args):
        asked.append((k, np.asarray(theta).tolist(), float(args[0])))
        return (jnp.asarray(5.5),) if k == 3 else None

    res = run_gradient_tuner(
        lambda th, a: jnp.sum(th) * 0.0 + a,
        jnp.zeros(2),
        (jnp.asarray(9.0),),
        optimizer="adam",
        steps=5,
        grad_tol=0.0,
        step_fn=_scripted(script, seen),
        hooks=TunerHooks(refresh=refresh),
    )
    assert [a[0] for a in asked] == [0, 1, 2, 3, 4]
    assert [a[1][0] for a in asked] == [0, 1, 0, 1, 2] and [a[2] for a in asked[-2:]] == [9, 5.5]
    assert [s[2] for s in seen] == [1.0, 1.0, 0.5, 1.0, 1.0]  # the halved step back to 1
    assert [s[1] for s in seen[3:]] == [2, 3]  # Adam's state kept across the refresh
    assert [float(s[3][0]) for s in seen] == [9.0, 9.0, 9.0, 5.5, 5.5]
    # the best since the refresh: 5 at (1, 0) (not the 1 at (0, 0) before it); the final
    # iterate (3, 0) has the loss 5.5 (the loss function's, of the new arguments): higher
    np.testing.assert_array_equal(res.theta, [1.0, 0.0])
    assert res.loss == 5.0 and res.n_bad == 1


def test_wall_time_counts_the_steps_only(monkeypatch):
    """Kills: the wall clock's start (0) and its sum: ``wall_s`` is the time spent in the steps
    so far, ``on_step``'s time left out (a stand-in clock: each step takes 0.5 s, each
    ``on_step`` call 10 s)."""
    from tuning import optim

    now = [100.0]
    monkeypatch.setattr(optim, "time", types.SimpleNamespace(perf_counter=lambda: now[0]))

    def step(theta, state, scale, args):
        now[0] += 0.5
        info = optim.StepInfo(jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(True), 1, 1.0)
        return theta, state, info

    def on_step(k, theta, rec):
        now[0] += 10.0

    res = optim.run_gradient_tuner(
        lambda th: jnp.sum(th), jnp.zeros(2), optimizer="adam", steps=3, step_fn=step,
        on_step=on_step,
    )  # fmt: skip
    assert [r["wall_s"] for r in res.history] == [0.5, 1.0, 1.5]


def test_settings_name_the_first_unknown_keyword_and_options_are_frozen():
    """Kills: the unknown keyword named (the first in sorted order), ``TunerOptions`` frozen
    (plain values, hashable: a setting cannot change under a running tuner)."""
    from tuning.optim import TunerOptions, run_gradient_tuner

    with pytest.raises(TypeError, match="argument 'another'$"):
        run_gradient_tuner(lambda th: jnp.sum(th), jnp.ones(1), zeta=1, another=2)
    opts = TunerOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.steps = 3
    assert hash(opts) == hash(TunerOptions())


def test_an_lbfgs_step_at_an_infinite_loss_is_rejected():
    """Kills: the L-BFGS step's guard ``isfinite(loss) & finite(gradient)`` (``|``): at a loss
    of +inf with a zero gradient the direction and the update are 0 (finite), yet the step is
    rejected (not ok, the input and state kept)."""
    from tuning.optim import init_state, make_optimizer, make_step

    opt = make_optimizer("lbfgs", memory_size=3, max_linesearch_steps=3)
    step = make_step(lambda th: jnp.where(th[0] > 0.5, jnp.inf, jnp.sum(th**2)), opt, "lbfgs")
    th = jnp.asarray([1.0, 0.0])
    st = init_state(opt, th)
    th1, st1, info = step(th, st, jnp.asarray(1.0), ())
    assert not bool(info.ok) and float(info.grad_norm) == 0.0 and float(info.update_norm) == 0.0
    np.testing.assert_array_equal(th1, th)
    for a, b in zip(jax.tree.leaves(st1), jax.tree.leaves(st), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("optimizer", ["adam", "lbfgs"])
def test_a_converged_run_returns_the_final_iterate_when_lower(optimizer):
    """Kills: the final iterate's evaluation after every stop but an abort or an interrupt
    (``reason != "interrupted"``: "converged" sorts before it): a run that converges at its
    second step returns the iterate that step made, lower than either input (Adam: in numpy;
    L-BFGS: the loss its state holds, the bowl's at that point)."""
    from tuning.optim import run_gradient_tuner

    c = np.array([0.0, 0.0])
    res = run_gradient_tuner(
        _bowl, jnp.asarray([3.0, 4.0]), (jnp.asarray(c),), optimizer=optimizer, steps=5,
        grad_tol=4.99,
    )  # fmt: skip
    assert res.reason == "converged"
    ins = [r["loss"] for r in res.history]
    assert res.loss < min(ins) and res.loss == pytest.approx(0.5 * np.sum(np.square(res.theta)))
    if optimizer == "adam":
        _, final = _adam_numpy(lambda th: th - c, [3.0, 4.0], len(ins), lr=0.05)
        np.testing.assert_allclose(res.theta, final, rtol=1e-12)


def test_an_lbfgs_run_takes_its_final_loss_from_its_state():
    """Kills: the final iterate's loss read from L-BFGS's state (where its last line search
    ended), not evaluated again: the loss function runs exactly ``evals`` times."""
    from tuning.optim import run_gradient_tuner

    ran = []

    def loss(th, c):
        jax.debug.callback(lambda: ran.append(1))
        return _bowl(th, c)

    res = run_gradient_tuner(
        loss, jnp.zeros(2), (jnp.asarray([1.0, -2.0]),), optimizer="lbfgs", steps=2
    )
    jax.effects_barrier()
    assert res.reason == "steps" and len(ran) == res.evals >= 3
