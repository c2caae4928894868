"""The programs of one registered loop and what building them costs: the forward rollout and
its gradient (``loop_programs``), traced, lowered and optionally compiled (``build_times``:
seconds and StableHLO lines). Shared by the graph-size budgets (``tests/test_graph_size.py``)
and the compile-time benchmark (``benchmarks/perf/compile_times.py``), which build the same
programs."""

from __future__ import annotations

import time

__all__ = ["DT", "build_times", "loop_programs", "program_eqns", "stage_stacks"]

#: the step [s] of the benchmarks' rollouts (``benchmarks/_common.py``)
DT = 0.05


def build_times(fn, *args, compile: bool = True) -> dict:
    """``trace_s``, ``lower_s``, ``compile_s`` and ``hlo_lines`` of ``jax.jit(fn)`` at ``args``.

    Older JAX without ``jit(f).trace`` lowers directly (trace time then counts in ``lower_s``
    and ``trace_s`` is 0).
    """
    import jax

    jitted = fn if hasattr(fn, "lower") else jax.jit(fn)
    t0 = time.perf_counter()
    if hasattr(jitted, "trace"):
        traced = jitted.trace(*args)
        t1 = time.perf_counter()
        lowered = traced.lower()
    else:
        t1 = t0
        lowered = jitted.lower(*args)
    t2 = time.perf_counter()
    if compile:
        lowered.compile()
    t3 = time.perf_counter()
    return {
        "trace_s": t1 - t0,
        "lower_s": t2 - t1,
        "compile_s": t3 - t2 if compile else None,
        "hlo_lines": len(lowered.as_text().splitlines()),
    }


def loop_programs(vehicle: str, controller: str, steps: int, timing: str, dt: float = DT):
    """``(forward, gradient, gains, sc)``: the two functions of one loop (the mean squared
    path error of a ``steps``-step RK4 rollout at ``dt``, and its value and gradient) and their
    inputs."""
    import jax
    import jax.numpy as jnp

    from vcjax import loops
    from vcjax.rollout import RolloutConfig

    loop = loops.make_loop(vehicle, controller)
    sc = loops.make_scenario(loop, loops.default_path(vehicle)[1])
    gains = loop.default_gains()
    cfg = RolloutConfig(num_steps=steps, integrator="rk4", timing=timing)

    def forward(gains, sc):
        tr = loops.simulate(loop, gains, sc, cfg, dt)
        eps = loop.signals(tr, sc).eps
        return jnp.mean(eps * eps)

    return forward, jax.value_and_grad(forward), gains, sc


def program_eqns(fn, *args):
    """``(eqn, in_stage)`` for every equation of ``fn``'s jaxpr at ``args``, nested jaxprs
    included; ``in_stage``: inside an RK4 stage loop (the body of a ``lax.scan`` of length 4)."""
    import jax
    from jax._src import core as jcore

    def walk(jaxpr, in_stage):
        for e in jaxpr.eqns:
            yield e, in_stage
            stage = in_stage or _is_stage_loop(e)
            for v in e.params.values():
                if isinstance(v, jcore.ClosedJaxpr | jcore.Jaxpr):
                    yield from walk(getattr(v, "jaxpr", v), stage)

    yield from walk(jax.make_jaxpr(fn)(*args).jaxpr, False)


def _is_stage_loop(eqn) -> bool:
    return eqn.primitive.name == "scan" and eqn.params["length"] == 4


def stage_stacks(fn, *args) -> int:
    """The most values any RK4 stage loop (a ``lax.scan`` of length 4) in ``fn``'s jaxpr at
    ``args`` stacks as outputs: under reverse mode, what the stages keep for the backward pass
    (0 when there is no stage loop)."""
    stacks = [
        len(e.outvars) - e.params["num_carry"]
        for e, _ in program_eqns(fn, *args)
        if _is_stage_loop(e)
    ]
    return max(stacks, default=0)
