"""Cost of a sea state: a REMUS 100 closed-loop sweep with and without waves (issue 23, item 6),
and the plant-side share.

**Closed loop** (``sweep`` rows, the figure the issue asks for): ``vcjax.sweep.run_batch`` of
``examples/sweeps/remus100_waves.toml`` (REMUS 100 on the survey leg, controller sampled at 20
Hz, RK4 plant, metrics streamed) over ``--sweep-batch`` scenarios x ``--sweep-steps`` steps,
timed in the same run for each controller with its 64-component sea (``sweep_waves``) and with
the ``[waves]`` section removed (``sweep_calm_water``: the same scenarios, the plant without a
sea), the two programs in turn (best of ``--repeats`` each); ``x_no_waves`` is the ratio of the
two run times (target: <= 2), per controller and for the whole sweep (every controller). The
sea is evaluated at the vehicle's position in every RK4 stage (four per step).

**Plant only** (``jit(vmap(scan(rk4)))`` of ``remus100_plant`` with fixed actuator commands, no
controller, so its ratio bounds a loop's from above):

* ``current``: the plant as every loop uses it without waves, a constant (2,) current;
* ``waves``: the same plant taking the water as its (3,) current, with
  ``vcjax.environment.waves.water_kinematics`` of a 64-component sea (one sea per scenario, drawn
  inside the jitted function by ``sea_state`` from the scenario's key) evaluated at the vehicle's
  position in every RK4 stage, plus ``current_door_correction`` (one extra Cholesky solve);
* ``waves_door_only``: as ``waves`` without the correction (what a plant that adds the
  correction to its force sum, sharing its one solve, costs);
* ``waves_only``: the kinematics alone (``water_kinematics`` summed over the same steps and
  stages, no plant), the marginal cost of the sea.

Deterministic measure: StableHLO lines of the whole program. Per RK4 stage and component the
sea costs one ``exp`` (the depth attenuation), one shared sin/cos range reduction (a ``round``)
with two short polynomials (``waves._sincos``, ~5x cheaper than ``jnp.cos`` + ``jnp.sin`` on
XLA:CPU) and ~30 multiply-adds. Timing: best of ``--repeats`` after a warm-up.

    .venv/bin/python -m benchmarks.perf.waves_cost [--batch 1024] [--steps 600] [--components 64]
        [--sweep-batch 256] [--sweep-steps 1200] [--json benchmarks/results/waves_cost.json]
"""

from __future__ import annotations

import argparse

from benchmarks import _common as C


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    C.add_common_args(p)
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--steps", type=int, default=600)
    p.add_argument("--components", type=int, default=64)
    p.add_argument("--sweep-batch", type=int, default=256, help="closed-loop sweep scenarios")
    p.add_argument("--sweep-steps", type=int, default=1200, help="closed-loop sweep steps")
    p.add_argument("--no-plant", action="store_true", help="only the closed-loop sweep rows")
    return p.parse_args(argv)


def _sweep_rows(args, batch: int, steps: int, repeats: int) -> list[dict]:
    """Closed-loop REMUS 100 sweep of the example config, with and without its sea."""
    import dataclasses
    import functools
    from pathlib import Path

    import jax
    import numpy as np

    from vcjax import sweep

    cfg = Path(__file__).resolve().parents[2] / "examples" / "sweeps" / "remus100_waves.toml"
    spec, _ = sweep.load_config(cfg)
    dt = spec.dt
    base = dataclasses.replace(
        spec, num_scenarios=batch, horizon=steps * dt, record_points=0, chunk_size=batch
    )
    sc = dataclasses.replace(base.scenario, wave_components=args.components)
    specs = {
        "sweep_waves": dataclasses.replace(base, scenario=sc),
        "sweep_calm_water": dataclasses.replace(base, scenario=sc.without_waves()),
    }
    rows, total = [], dict.fromkeys(specs, 0.0)
    for variant in spec.variants:
        progs = {}
        for name, sp in specs.items():
            loop = sp.loop(variant)
            nom = sweep.nominal(sp)
            dtype = jax.tree_util.tree_leaves(nom[1])[0].dtype
            scen = sweep.sample_scenarios(sp.scenario, sp.seed, np.arange(batch), dtype, loop)
            fn = functools.partial(
                sweep.run_batch,
                loop,
                loop.default_gains(),
                nom,
                config=sp.mc_config(),
                dt=dt,
                diverge_e=sp.diverge_e,
            )
            jitted = jax.jit(fn)
            lower_s, compile_s, compiled = C.compile_timed(jitted, scen)
            lines = len(jitted.lower(scen).as_text().splitlines())
            m = jax.device_get(compiled(scen)[0])  # (and the warm-up)
            progs[name] = (compiled, scen, lower_s + compile_s, lines, int(np.sum(m["diverged"])))
        # the two programs timed in turn, best of each: a load that drifts during the run
        # weighs on both alike
        best = dict.fromkeys(progs, float("inf"))
        for _ in range(repeats):
            for name, (compiled, scen, *_rest) in progs.items():
                best[name] = min(best[name], C.best_of(lambda c=compiled, s=scen: c(s), 1, 0))
        for name, (_c, _s, comp, lines, diverged) in progs.items():
            total[name] += best[name]
            rows.append(dict(variant=f"{name} {variant}", batch=batch, steps=steps,
                             stablehlo_lines=lines, compile_s=comp, run_s=best[name],
                             us_per_scenario_step=1e6 * best[name] / (batch * steps),
                             x_no_waves=best[name] / best["sweep_calm_water"],
                             diverged=diverged, load=C.load_average()))  # fmt: skip
    for name, run_s in total.items():  # the whole sweep: every controller
        rows.append(dict(variant=f"{name} (all controllers)", batch=batch, steps=steps,
                         run_s=run_s, us_per_scenario_step=1e6 * run_s / (batch * steps),
                         x_no_waves=run_s / total["sweep_calm_water"],
                         load=C.load_average()))  # fmt: skip
    return rows


def _programs(components: int, steps: int):
    import jax
    import jax.numpy as jnp

    from vcjax.environment import WaterMotion, waves
    from vcjax.linalg import spd_solve_small
    from vcjax.vehicles import remus100, sixdof

    p = remus100.remus100_params(dtype=jnp.zeros(0).dtype)
    dtype = p.rho.dtype
    dt = jnp.asarray(0.05, dtype)
    cmd = jnp.asarray([0.02, -0.03, 1200.0], dtype)
    m_d = p.body.B / p.body.W * p.body.M_RB[0, 0]

    def rk4(f, t, x):
        add = lambda x, k, h: jax.tree.map(lambda a, b: a + h * b, x, k)
        k1 = f(t, x)
        k2 = f(t + dt / 2, add(x, k1, dt / 2))
        k3 = f(t + dt / 2, add(x, k2, dt / 2))
        k4 = f(t + dt, add(x, k3, dt))
        return add(x, jax.tree.map(lambda a, b, c, d: (a + 2 * b + 2 * c + d) / 6,
                                   k1, k2, k3, k4), dt)  # fmt: skip

    def x0(depth):
        eta = jnp.zeros(6, dtype).at[2].set(depth)
        nu = jnp.zeros(6, dtype).at[0].set(1.5)
        return remus100.Remus100State(eta, nu, jnp.zeros(3, dtype))

    def run(field, depth):
        ts = jnp.arange(steps, dtype=dtype) * dt
        xf, _ = jax.lax.scan(lambda x, t: (rk4(field, t, x), None), x0(depth), ts)
        return xf.eta[2]

    def with_current(key, hs, tp, beta, v_c, depth):
        args = remus100.Remus100Args(p, WaterMotion(v_c, jnp.zeros(3, dtype)))
        return run(lambda t, x: remus100.remus100_plant(t, x, cmd, args), depth)

    def with_waves(key, hs, tp, beta, v_c, depth, correction=True):
        sea = waves.sea_state(key, hs, tp, beta, components=components)

        def field(t, x):
            v_w, a_w = water = waves.water_kinematics(sea, t, x.eta[:3], v_c)
            still = WaterMotion(jnp.zeros(3, dtype), jnp.zeros(3, dtype))  # all rotated in full
            dx = remus100.remus100_plant(t, x, cmd, remus100.Remus100Args(p, water, uniform=still))
            if not correction:
                return dx
            R = sixdof.Rzyx(x.eta[3], x.eta[4], x.eta[5])
            corr = waves.current_door_correction(R, a_w, p.body.M_RB, m_d, p.body.r_bb)
            return dx._replace(nu=dx.nu + spd_solve_small(remus100.mass_matrix(p), corr))

        return run(field, depth)

    def door_only(*a):
        return with_waves(*a, correction=False)

    def waves_only(key, hs, tp, beta, v_c, depth):
        sea = waves.sea_state(key, hs, tp, beta, components=components)

        def f(t, y):  # y: a position moving with the current; the kinematics summed
            v_w, a_w = waves.water_kinematics(sea, t, y[:3], v_c)
            return jnp.concatenate([v_c, v_w + a_w])

        ts = jnp.arange(steps, dtype=dtype) * dt
        y0 = jnp.zeros(6, dtype).at[2].set(depth)
        yf, _ = jax.lax.scan(lambda y, t: (rk4(f, t, y), None), y0, ts)
        return yf[3]

    return {
        "current": with_current,
        "waves": with_waves,
        "waves_door_only": door_only,
        "waves_only": waves_only,
    }


def _inputs(batch: int, seed: int = 0):
    import jax
    import jax.numpy as jnp

    k = jax.random.split(jax.random.key(seed), 5)
    dtype = jnp.zeros(0).dtype
    u = lambda k, lo, hi, shape=(batch,): jax.random.uniform(k, shape, dtype, lo, hi)
    v_c = jnp.concatenate([u(k[3], -0.3, 0.3, (batch, 2)), jnp.zeros((batch, 1), dtype)], 1)
    return (jax.random.split(k[0], batch), u(k[1], 0.5, 3.0), u(k[2], 5.0, 12.0),
            u(k[4], -3.0, 3.0), v_c, jnp.full((batch,), 5.0, dtype))  # fmt: skip


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype)
    import jax

    batch, steps = (64, 100) if args.quick else (args.batch, args.steps)
    repeats = 2 if args.quick else args.repeats
    sweep_size = (32, 200) if args.quick else (args.sweep_batch, args.sweep_steps)
    sweep_rows = _sweep_rows(args, *sweep_size, repeats)
    cols = ["variant", "batch", "steps", "stablehlo_lines", "compile_s", "run_s",
            "us_per_scenario_step", "x_no_waves", "diverged", "load"]  # fmt: skip
    title = f"closed-loop REMUS 100 sweep, {args.components}-component sea, {args.dtype}, "
    C.print_table(sweep_rows, cols, title + C.device_str())
    if args.no_plant:
        C.write_json(args.json, args, sweep_rows)
        return
    inputs = _inputs(batch)
    rows = []
    for name, fn in _programs(args.components, steps).items():
        jitted = jax.jit(jax.vmap(fn))
        lower_s, compile_s, compiled = C.compile_timed(jitted, *inputs)
        text = jitted.lower(*inputs).as_text()
        run_s = C.best_of(lambda compiled=compiled: compiled(*inputs), repeats)
        stablehlo = len(text.splitlines())
        rows.append(dict(variant=name, batch=batch, steps=steps, stablehlo_lines=stablehlo,
                         compile_s=lower_s + compile_s, run_s=run_s,
                         us_per_scenario_step=1e6 * run_s / (batch * steps),
                         load=C.load_average()))  # fmt: skip
    base = rows[0]["run_s"]
    for r in rows:
        r["x_current"] = r["run_s"] / base
    cols = ["variant", "batch", "steps", "stablehlo_lines", "compile_s", "run_s",
            "us_per_scenario_step", "x_current", "load"]  # fmt: skip
    C.print_table(
        rows, cols, f"plant only, {args.components}-component sea, {args.dtype}, {C.device_str()}"
    )
    C.write_json(args.json, args, sweep_rows + rows)  # the closed-loop sweep rows first


if __name__ == "__main__":
    main()
