"""The tuner's gradient on a batch sharded over several CPU devices: gains shared by the
``vmap`` against gains tiled per scenario (``TuningProblem.tile_gains``, what ``vcjax tune`` uses
when it shards), and against one device.

With shared gains and a sharded batch, XLA reduces the gains' cotangent across devices at every
step of the backward scan (an ``all-reduce`` inside the loop body); tiled, each device
accumulates per scenario and the reduction happens once. For each case: ``value_and_grad`` of
``mean_b sum_k (s^2 + e^2) dt`` w.r.t. the VCM gains (Simulation 1's ``vcm_integral``, RK4,
continuous controller), the best wall time of ``--repeats`` after a warm-up, and the number of
``all-reduce`` instructions inside ``while`` bodies of the compiled program.

    python -m benchmarks.perf.sharded_gradient --json benchmarks/results/sharded_gradient.json
"""

from __future__ import annotations

import argparse

from benchmarks import _common as C
from tests.reference.hlo import loop_allreduces

COLUMNS = ["gains", "devices", "batch", "steps", "dtype", "run_s", "compile_s", "loop_allreduce"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--batch", type=int, default=48, help="scenarios (the acceptance tune's 48)")
    p.add_argument("--steps", type=int, default=800)
    p.add_argument("--cpu-devices", type=int, default=2)
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.steps, args.repeats = 8, 100, 2
    return args


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype, args.cpu_devices)
    import jax
    import jax.numpy as jnp
    import numpy as np

    from vcjax import experiments, loops
    from vcjax.rollout import RolloutConfig

    B, N = args.batch, args.steps
    gains, sc = C.base_inputs()
    pm, scb = gains.vcm, C.batched_scenario(sc, B)
    axes = C.scenario_axes(scb)
    sim1 = experiments.get("sim1")
    base, loop = sim1.default_gains(C.VARIANT), sim1.loop(C.VARIANT)
    scs = C.shard_batch(scb, len(jax.devices()))

    def one(g, s, dt):
        cfg = RolloutConfig(num_steps=N, integrator="rk4", timing="continuous")
        tr = loops.simulate(loop, base._replace(vcm=g), s, cfg, dt)
        return jnp.sum(tr.aux.eps**2) * dt

    def shared(g, s, dt):
        return jnp.mean(jax.vmap(one, in_axes=(None, axes, None))(g, s, dt))

    def tiled(g, s, dt):
        gb = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (B, *jnp.shape(a))), g)
        return jnp.mean(jax.vmap(one, in_axes=(0, axes, None))(gb, s, dt))

    rows, grads = [], {}
    for name, lf in (("shared", shared), ("tiled", tiled)):
        for n_dev, s in ((1, scb), (len(jax.devices()), scs)):
            f = jax.jit(jax.value_and_grad(lf))
            lower_s, compile_s, comp = C.compile_timed(f, pm, s, C.DT)
            run_s = C.best_of(lambda comp=comp, s=s: comp(pm, s, C.DT), args.repeats)
            grads[(name, n_dev)] = np.concatenate(
                [np.ravel(x) for x in jax.tree_util.tree_leaves(comp(pm, s, C.DT)[1])]
            )
            rows.append(
                {
                    "gains": name,
                    "devices": n_dev,
                    "batch": B,
                    "steps": N,
                    "dtype": args.dtype,
                    "run_s": run_s,
                    "compile_s": lower_s + compile_s,
                    "loop_allreduce": loop_allreduces(comp.as_text()),
                    "load": C.load_average(),
                }
            )
            print(f"  {name:<7} {n_dev} device(s): {run_s:.3f} s", flush=True)
    ref = grads[("shared", 1)]
    for r in rows:
        g = grads[(r["gains"], r["devices"])]
        r["grad_rel_diff"] = float(np.max(np.abs(g - ref)) / np.max(np.abs(ref)))
    C.print_table(rows, [*COLUMNS, "grad_rel_diff"], "value_and_grad: shared vs tiled gains")
    C.write_json(args.json, args, rows)
    return rows


if __name__ == "__main__":
    main()
