"""Throughput of every closed loop: each (vehicle, controller) of the loop registry
(:mod:`vcjax.loops`: INFANTE, ODIN, REMUS 100, the arm); single trajectory, a batch on one
core, the same batch on every core.

The process splits the host CPU into ``--cpu-devices`` JAX devices (default: one per core,
:mod:`vcjax.runtime.devices`) before JAX starts. ``vmap`` rows run the batch on one device
(one core);
``sharded`` rows shard the same batch over every device (``NamedSharding`` along the scenario
axis, as ``vcjax sweep`` does); ``cores_used`` says which. RK4, dt = 0.05 s, the controller
``--timing`` (default sampled: once per step, held, as on a vehicle); batches are the loop's
default scenario with random position offsets (N(0, 5 m)) and currents (|V_c| ~ U(0, 0.5) m/s).
Each timed function returns only a (B,) reduction of the trajectory (computed in jit).

    python -m benchmarks.perf.loops --json benchmarks/results/loops_float32.json
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import _common as C

COLUMNS = [
    "loop",
    "timing",
    "kind",
    "batch",
    "cores_used",
    "steps",
    "compile_s",
    "run_s",
    "steps_per_s",
    "cpu_s",
    "load",
]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--batch", type=int, default=4096)
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--single-steps", type=int, default=2000)
    p.add_argument("--timing", choices=("continuous", "sampled"), default="sampled")
    p.add_argument("--cpu-devices", type=int, default=None, help="default: one per core")
    p.add_argument("--loops", nargs="+", default=None, help="vehicle/controller names to run")
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.steps, args.single_steps = 512, 100, 400
        args.repeats = min(args.repeats, 2)
    return args


def _offsets(batch: int, dtype, seed=0):
    rng = np.random.default_rng(seed)
    d_xy = rng.normal(size=(batch, 2)) * 5.0
    ang = rng.uniform(-np.pi, np.pi, batch)
    mag = rng.uniform(0.0, 0.5, batch)
    cur = np.stack([mag * np.cos(ang), mag * np.sin(ang), np.zeros(batch)], axis=1)
    return d_xy.astype(dtype), cur.astype(dtype)


def registry_cases(timing: str, names=None):
    """``(name, one, sc0, make_batch)`` for every registered loop: ``one(sc, n)`` rolls one
    scenario out (static ``n`` steps) and returns a scalar."""
    import jax
    import jax.numpy as jnp

    from vcjax import loops
    from vcjax.rollout import RolloutConfig

    out = []
    for vehicle in loops.vehicles():
        for ctrl in loops.controllers(vehicle):
            name = f"{vehicle}/{ctrl}"
            if names and name not in names and vehicle not in names:
                continue
            try:
                loop = loops.make_loop(vehicle, ctrl)
                sc0 = loops.make_scenario(loop, loops.default_path(vehicle)[1])
            except (TypeError, ValueError) as err:  # a loop that needs more than defaults
                print(f"  skipped {name}: {err}")
                continue
            gains = loop.default_gains()

            def one(sc, n, loop=loop, gains=gains):
                cfg = RolloutConfig(num_steps=n, integrator="rk4", timing=timing)
                tr = loops.simulate(loop, gains, sc, cfg, C.DT)
                return jnp.mean(jnp.abs(loop.signals(tr, sc).eps[:, 1]))

            def make_batch(batch, sc0=sc0):
                d_xy, cur = _offsets(batch, np.dtype(sc0.eta0.dtype))
                eta0 = jnp.asarray(sc0.eta0)[None, :].repeat(batch, 0)
                eta0 = eta0.at[:, :2].add(jnp.asarray(d_xy))
                cur = jnp.asarray(cur[:, : sc0.current.shape[-1]])
                axes = jax.tree_util.tree_map(lambda _: None, sc0)._replace(eta0=0, current=0)
                return sc0._replace(eta0=eta0, current=cur), axes

            out.append((name, one, sc0, make_batch))
    return out


def _time(name, kind, f, inputs, batch, steps, cores, args):
    lower_s, compile_s, comp = C.compile_timed(f, *inputs)
    run_s = C.best_of(lambda: comp(*inputs), args.repeats)
    row = {
        "loop": name,
        "timing": args.timing,
        "kind": kind,
        "batch": batch,
        "cores_used": cores,
        "steps": steps,
        "dtype": args.dtype,
        "compile_s": lower_s + compile_s,
        "run_s": run_s,
        "steps_per_s": batch * steps / run_s,
        "cpu_s": C.LAST_CPU_S,
        "load": C.load_average(),
    }
    print(f"  {name:<24} {kind:<8} cores {cores}: {row['steps_per_s']:.3e} steps/s", flush=True)
    return row


def main(argv=None):
    args = parse_args(argv)
    from vcjax.runtime.devices import cpu_device_count

    C.setup(args.dtype, cpu_device_count(args.cpu_devices))
    import jax
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    n_dev = len(jax.devices())
    cases = registry_cases(args.timing, args.loops)
    rows = []
    mesh = Mesh(np.asarray(jax.devices()), ("scenarios",))
    sharding = NamedSharding(mesh, PartitionSpec("scenarios"))
    for name, one, sc0, make_batch in cases:
        f1 = jax.jit(lambda sc, one=one: one(sc, args.single_steps))
        rows.append(_time(name, "single", f1, (sc0,), 1, args.single_steps, 1, args))
        scb, axes = make_batch(args.batch)
        fb = jax.jit(
            lambda s, one=one, axes=axes: jax.vmap(lambda x: one(x, args.steps), (axes,))(s)
        )
        rows.append(_time(name, "vmap", fb, (scb,), args.batch, args.steps, 1, args))
        if n_dev > 1 and args.batch % n_dev == 0:
            put = lambda ax, a: a if ax is None else jax.device_put(a, sharding)
            scs = jax.tree_util.tree_map(put, axes, scb, is_leaf=lambda x: x is None)
            rows.append(_time(name, "sharded", fb, (scs,), args.batch, args.steps, n_dev, args))
    C.print_table(rows, COLUMNS, f"closed-loop throughput per loop ({args.dtype}, {args.timing})")
    C.write_json(args.json, args, rows)
    return rows


if __name__ == "__main__":
    main()
