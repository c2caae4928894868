"""XLA's cost analysis of the closed-loop step, the machine's matmul rate, and a breakdown.

1. Flops per closed-loop step from ``compiled.cost_analysis()`` of the batched rollout. On this
   XLA, HloCostAnalysis counts a ``while`` body once (not times its trip count): the flops of
   programs with different horizons are fitted as ``a + b N``; if ``b`` is per-step sized the
   per-step cost is ``b / B``, otherwise ``a / B`` (the body counted once plus a small fixed
   part). Both raw numbers are reported.
   Kernels per step: the top-level instructions of the compiled ``while`` body that launch
   work (``fusion``, ``dot``, ``custom-call`` such as LAPACK, ``call``), counted in
   ``compiled.as_text()`` for each controller timing, batched and single.
2. The achieved rate (flops/step x measured steps/s) as a fraction of the machine's measured
   float32 matmul rate (jitted ``n x n @ n x n``, best of repeats).
3. A breakdown by component, each vmapped over the batch and iterated ``--iters`` times in a
   ``fori_loop`` (state nudged each iteration so nothing is hoisted): the INFANTE-class plant
   vector field, the VCM law (with the actuator map), the path frame alone, and the plant's
   3x3 ``jnp.linalg.solve`` against a precomputed inverse. A full RK4 step evaluates plant and
   controller 4 times each.

    python -m benchmarks.perf.cost_analysis --dtype float32 --json results/cost_f32.json
"""

from __future__ import annotations

import argparse
import re

from benchmarks import _common as C


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--batch", type=int, default=4096)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--matmul-n", type=int, default=2048)
    p.add_argument("--iters", type=int, default=100, help="iterations of each component loop")
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.steps, args.matmul_n, args.iters = 1024, 200, 1024, 50
        args.repeats = min(args.repeats, 2)
    return args


def matmul_rate(n: int, repeats: int) -> dict:
    """Best float32 ``n x n`` matmul rate [flop/s] (2 n^3 flops per product)."""
    import jax
    import jax.numpy as jnp

    a = jax.random.normal(jax.random.PRNGKey(0), (n, n), jnp.float32)
    b = jax.random.normal(jax.random.PRNGKey(1), (n, n), jnp.float32)
    f = jax.jit(jnp.matmul).lower(a, b).compile()
    t = C.best_of(lambda: f(a, b), max(repeats, 3))
    return {"n": n, "best_s": t, "flops_per_s": 2.0 * n**3 / t, "cpu_s": C.LAST_CPU_S}


def step_flops(batch: int, timing: str = "continuous") -> dict:
    """Flops of the batched rollout for several horizons; per trajectory-step estimate."""
    import jax

    gains, sc = C.base_inputs()
    scb = C.batched_scenario(sc, batch)
    raw = {}
    for n in (10, 100, 1000):
        comp = jax.jit(C.metric_fn(n, timing=timing)).lower(gains, scb, C.DT).compile()
        ca = C.cost(comp)
        raw[n] = {
            "flops": float(ca.get("flops", 0.0)),
            "transcendentals": float(ca.get("transcendentals", 0.0)),
            "bytes_accessed": float(ca.get("bytes accessed", 0.0)),
        }
    slope = (raw[1000]["flops"] - raw[100]["flops"]) / 900.0
    body_once = slope / batch < 100.0  # a closed-loop step is ~thousands of flops
    if body_once:
        intercept = raw[100]["flops"] - 100 * slope
        per_step = intercept / batch
        per_step_tr = raw[100]["transcendentals"] / batch
        per_step_bytes = (raw[100]["bytes_accessed"] - 100 * 0) / batch
    else:
        per_step = slope / batch
        per_step_tr = (raw[1000]["transcendentals"] - raw[100]["transcendentals"]) / 900 / batch
        per_step_bytes = (raw[1000]["bytes_accessed"] - raw[100]["bytes_accessed"]) / 900 / batch
    return {
        "batch": batch,
        "timing": timing,
        "raw_by_horizon": raw,
        "while_body_counted_once": body_once,
        "flops_per_step": per_step,
        "transcendentals_per_step": per_step_tr,
        "bytes_per_step_upper": per_step_bytes,
    }


#: opcodes of a ``while`` body's top-level instructions that each run as one kernel on the CPU
KERNEL_OPS = ("fusion", "dot", "custom-call", "call", "convolution", "sort", "scatter", "gather")


def while_bodies(hlo_text: str) -> list[str]:
    """The text of every ``while`` body computation in an optimised HLO module's text."""
    names = re.findall(r"\bwhile\(.*?body=%?([\w.\-]+)", hlo_text)
    blocks = dict(re.findall(r"^%?([\w.\-]+) [^\n]*\{\n(.*?)^\}", hlo_text, re.S | re.M))
    return [blocks.get(n, "") for n in names]


def while_body_kernels(hlo_text: str) -> dict:
    """Count the kernels of the largest ``while`` body in an optimised HLO module's text: its
    top-level instructions by opcode (``KERNEL_OPS``; everything else, e.g. tuples, bitcasts,
    parameters and constants, launches nothing)."""
    best = {}
    for body in while_bodies(hlo_text):
        counts = dict.fromkeys(KERNEL_OPS, 0)
        for line in body.splitlines():
            m = re.match(r"\s*(?:ROOT )?%?[\w.\-]+ = [^=]*?\s([a-z\-]+)\(", line)
            if m and m.group(1) in counts:
                counts[m.group(1)] += 1
        counts = {k: v for k, v in counts.items() if v}
        if sum(counts.values()) > sum(best.values()):
            best = counts
    return {**best, "total": sum(best.values())}


def kernel_rows(batch: int) -> list[dict]:
    """Kernels per closed-loop step for each controller timing, single and batched."""
    import jax

    gains, sc = C.base_inputs()
    rows = []
    for timing in ("continuous", "sampled"):
        for b in (1, batch):
            f = C.metric_fn(100, batched=b > 1, timing=timing)
            s = C.batched_scenario(sc, b) if b > 1 else sc
            comp = jax.jit(f).lower(gains, s, C.DT).compile()
            k = while_body_kernels(comp.as_text())
            rows.append({"timing": timing, "batch": b, **k})
    return rows


def _loop_time(body, init, iters, repeats):
    import jax

    f = jax.jit(lambda s: jax.lax.fori_loop(0, iters, lambda i, s: body(s), s))
    comp = f.lower(init).compile()
    t = C.best_of(lambda: comp(init), repeats)
    ca = C.cost(comp)
    return t, float(ca.get("flops", 0.0))


def components(batch: int, iters: int, repeats: int) -> list[dict]:
    """Time per trajectory-evaluation of each component, vmapped over ``batch``."""
    import jax
    import jax.numpy as jnp

    from vcjax import paths
    from vcjax.control.vcm import VCMConfig, vcm_law, vcm_params, vcm_state
    from vcjax.environment import WaterMotion
    from vcjax.vehicles import infante

    gains, sc = C.base_inputs()
    scb = C.batched_scenario(sc, batch)
    veh = sc.plant
    dtype = sc.eta0.dtype
    eps_ = jnp.asarray(1e-6, dtype)
    nu = jnp.broadcast_to(sc.nu0, (batch, 3))
    x = infante.InfanteState(eta=scb.eta0, nu=nu, act=jnp.zeros((batch, 2), dtype))
    water = WaterMotion(scb.current, jnp.zeros((batch, 3), dtype))
    args = infante.PlantArgs(vehicle=veh, water=water)
    u_cmd = jnp.broadcast_to(jnp.asarray([500.0, 0.1], dtype), (batch, 2))
    Y, N = infante.rudder_gains(veh, jnp.array([1.0, 0.0, 0.0], dtype))
    cp = vcm_params(gains.vcm, infante.design_model(veh), sc.path, u_d=sc.u_d, k_rudder=Y / N)
    cfg = VCMConfig(path=paths.LINE, actuation="underactuated", integral=True)
    z = jax.vmap(lambda w: vcm_state(varpi0=0.0)._replace(varpi=w))(scb.eta0[:, 1])

    def plant_body(s):
        xs, a = s
        a_axes = infante.PlantArgs(vehicle=None, water=0)
        xd = jax.vmap(infante.infante_plant, in_axes=(None, 0, 0, a_axes))(0.0, xs, u_cmd, a)
        return jax.tree_util.tree_map(lambda p, q: p + eps_ * q, xs, xd), a

    def ctrl_one(x1, z1):
        tau, z_dot, aux = vcm_law(cfg, cp, 0.0, x1.eta, x1.nu, z1)
        return infante.actuator_commands(veh, x1.nu, tau[0], tau[2]), z_dot

    def ctrl_body(s):
        xs, zs = s
        u, zd = jax.vmap(ctrl_one)(xs, zs)
        zs = jax.tree_util.tree_map(lambda p, q: p + eps_ * q, zs, zd)
        return xs._replace(nu=xs.nu + eps_ * jnp.pad(u, ((0, 0), (0, 1)))), zs

    def forces_body(s):
        xs, a = s
        f = jax.vmap(lambda n, ac: infante.body_forces(veh, n, ac))(xs.nu, xs.act)
        return xs._replace(nu=xs.nu + eps_ * f), a

    def crossflow_body(s):
        xs, a = s
        y, n = jax.vmap(lambda n: infante.crossflow_forces(veh, n[1], n[2]))(xs.nu)
        return xs._replace(nu=xs.nu + eps_ * jnp.stack([y, n, y], axis=1)), a

    def frame_body(w):
        fr = jax.vmap(lambda w1: paths.path_frame(paths.LINE, sc.path, w1))(w)
        return w + eps_ * (fr.psi_p + fr.dpsi_dw + fr.d2psi_dw2 + fr.speed_bar + fr.p_bar[:, 0])

    M = infante.mass_matrix(veh)
    Minv = jnp.linalg.inv(M)
    f0 = jnp.ones((batch, 3), dtype)

    def solve_body(f):
        return f + eps_ * jax.vmap(lambda b: jnp.linalg.solve(M, b))(f)

    def inv_body(f):
        return f + eps_ * (f @ Minv.T)

    cases = [
        ("plant vector field", plant_body, (x, args)),
        ("  plant: body_forces", forces_body, (x, args)),
        ("  plant: cross-flow drag (closed form)", crossflow_body, (x, args)),
        ("VCM law + actuator map", ctrl_body, (x, z)),
        ("path frame (line)", frame_body, z.varpi),
        ("3x3 jnp.linalg.solve", solve_body, f0),
        ("3x3 precomputed inverse", inv_body, f0),
    ]
    rows = []
    for name, body, init in cases:
        t, flops = _loop_time(body, init, iters, repeats)
        rows.append(
            {
                "component": name,
                "batch": batch,
                "iters": iters,
                "ns_per_eval": t / (iters * batch) * 1e9,
                "evals_per_s": iters * batch / t,
                "xla_flops_per_eval": flops / batch,  # fori body counted once
                "cpu_s": C.LAST_CPU_S,
            }
        )
        print(f"  {name}: {rows[-1]['ns_per_eval']:.1f} ns", flush=True)
    return rows


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype)
    from benchmarks.perf import throughput as T

    mm = matmul_rate(args.matmul_n, args.repeats)
    print(f"float32 matmul {args.matmul_n}: {mm['flops_per_s'] / 1e9:.1f} GFLOP/s", flush=True)
    summaries, flops, runs = [], {}, {}
    for timing in ("continuous", "sampled"):
        fl = flops[timing] = step_flops(args.batch, timing)
        run = runs[timing] = T.batched_rollout(
            args.batch, args.steps, args.repeats, args.dtype, timing
        )
        achieved = fl["flops_per_step"] * run["steps_per_s"]
        summaries.append(
            {
                "timing": timing,
                "dtype": args.dtype,
                "device": C.device_str(),
                "batch": args.batch,
                "flops_per_step": fl["flops_per_step"],
                "transcendentals_per_step": fl["transcendentals_per_step"],
                "steps_per_s": run["steps_per_s"],
                "steps_per_cpu_s": args.batch * args.steps / run["cpu_s"],
                "achieved_GFLOP_s": achieved / 1e9,
                "matmul_f32_GFLOP_s": mm["flops_per_s"] / 1e9,
                "fraction_of_matmul": achieved / mm["flops_per_s"],
                "steps_per_s_at_matmul_rate": mm["flops_per_s"] / fl["flops_per_step"],
                "load": C.load_average(),
            }
        )
    C.print_table(summaries, list(summaries[0]), "flops per closed-loop step vs matmul rate")
    for timing, fl in flops.items():
        print(f"  {timing}: XLA while body counted once: {fl['while_body_counted_once']}; raw:")
        for n, r in fl["raw_by_horizon"].items():
            print(f"     N={n}: {r})")
    run = runs["continuous"]
    kern = kernel_rows(args.batch)
    C.print_table(
        kern,
        ["timing", "batch", "total", *[k for k in KERNEL_OPS if any(k in r for r in kern)]],
        "kernels per closed-loop step (top-level instructions of the compiled while body)",
    )
    comp = components(args.batch, args.iters, args.repeats)
    step_ns = 1e9 / run["steps_per_s"]
    for r in comp:
        r["x4_share_of_step"] = 4 * r["ns_per_eval"] / step_ns
    C.print_table(
        comp,
        ["component", "batch", "iters", "ns_per_eval", "xla_flops_per_eval", "x4_share_of_step"],
        f"component breakdown (closed-loop RK4 step: {step_ns:.0f} ns per trajectory-step)",
    )
    C.write_json(
        args.json,
        args,
        summaries,
        flops=flops,
        matmul=mm,
        components=comp,
        rollout=runs,
        kernels=kern,
    )
    return summaries, comp


if __name__ == "__main__":
    main()
