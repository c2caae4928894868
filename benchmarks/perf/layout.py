"""What ``vmap``'s batch-first layout costs on this CPU: one toy closed loop, three ways.

A 12-state loop (3-DOF planar vehicle with quadratic damping and Coriolis terms, six
first-order controller states), RK4, ``--steps`` steps, ``--batch`` trajectories, float32:

* ``vmap``: the per-trajectory function (states as a (12,) vector, components indexed, the
  derivative built with ``jnp.stack``) ``jax.vmap``-ed. Every per-trajectory vector becomes a
  ``(B, k)`` array with the batch *first*: component ``i`` of all trajectories is a strided
  column, and each small ``stack`` writes a ``(B, k)`` buffer;
* ``vmap, scan outside``: the same with the ``lax.scan`` outside the ``vmap`` (the carry
  visible as one ``(B, 12)`` array);
* ``batch last``: the *same Python function* applied to a ``(12, B)`` array without ``vmap``
  (it only indexes components and combines them elementwise, so it is batch-agnostic): every
  component is a contiguous ``(B,)`` row.

The three give identical states (checked). The ratio ``batch last / vmap`` is what writing the
plant and the law on ``(n, B)`` arrays could gain over ``vmap`` (see ``benchmarks/README.md``,
"What limits the rest").

    python -m benchmarks.perf.layout --batch 4096 --steps 500
"""

from __future__ import annotations

import argparse

from benchmarks import _common as C


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--batch", type=int, default=4096)
    p.add_argument("--steps", type=int, default=500)
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.steps, args.repeats = 256, 50, 2
    return args


def toy_field(x):
    """(12,) -> (12,): works on (12,) and, unchanged, on (12, B)."""
    import jax.numpy as jnp

    psi, u, v, r = x[2], x[3], x[4], x[5]
    c, s = jnp.cos(psi), jnp.sin(psi)
    fu = -0.1 * u * jnp.abs(u) + 0.3 * v * r + x[6] - 0.2 * x[7]
    fv = -0.5 * v * jnp.abs(v) - 0.8 * u * r + 0.1 * x[8]
    fr = -0.3 * r * jnp.abs(r) + 0.05 * u * v - 0.4 * x[9] + 0.1 * jnp.tanh(x[10])
    ctrl = [
        -x[6] + 0.1 * u,
        -x[7] + 0.2 * v,
        -x[8] + r,
        -x[9] + psi,
        -x[10] + 0.01 * x[0],
        -x[11] + 0.01 * x[1],
    ]
    return jnp.stack([c * u - s * v, s * u + c * v, r, fu, fv, fr, *ctrl])


def rk4(x, h):
    k1 = toy_field(x)
    k2 = toy_field(x + h / 2 * k1)
    k3 = toy_field(x + h / 2 * k2)
    k4 = toy_field(x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def programs(steps: int, h: float = 0.05) -> dict:
    import jax

    def roll(x0):
        return jax.lax.scan(lambda x, _: (rk4(x, h), None), x0, None, length=steps)[0]

    step_b = jax.vmap(lambda x: rk4(x, h))
    return {
        "vmap": (jax.jit(jax.vmap(roll)), False),
        "vmap, scan outside": (
            jax.jit(lambda X: jax.lax.scan(lambda X, _: (step_b(X), None), X, None, steps)[0]),
            False,
        ),
        "batch last": (jax.jit(roll), True),
    }


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype)
    import jax.numpy as jnp
    import numpy as np

    dtype = jnp.dtype(args.dtype)
    X = jnp.asarray(np.random.default_rng(0).normal(size=(args.batch, 12)), dtype)
    rows, ref = [], None
    for name, (f, transposed) in programs(args.steps).items():
        x_in = X.T if transposed else X
        lower_s, compile_s, comp = C.compile_timed(f, x_in)
        run_s = C.best_of(lambda comp=comp, x_in=x_in: comp(x_in), args.repeats)
        out = np.asarray(comp(x_in))
        out = out.T if transposed else out
        ref = out if ref is None else ref
        rows.append(
            {
                "layout": name,
                "batch": args.batch,
                "steps": args.steps,
                "dtype": args.dtype,
                "device": C.device_str(),
                "compile_s": lower_s + compile_s,
                "run_s": run_s,
                "steps_per_s": args.batch * args.steps / run_s,
                "cpu_s": C.LAST_CPU_S,
                "steps_per_cpu_s": args.batch * args.steps / C.LAST_CPU_S,
                "max_abs_diff": float(np.max(np.abs(out - ref))),
                "load": C.load_average(),
            }
        )
    base = rows[0]["steps_per_cpu_s"]
    for r in rows:
        r["x_vmap_per_cpu_s"] = r["steps_per_cpu_s"] / base
    C.print_table(
        rows,
        [
            "layout",
            "batch",
            "steps",
            "dtype",
            "device",
            "compile_s",
            "steps_per_s",
            "steps_per_cpu_s",
            "x_vmap_per_cpu_s",
            "max_abs_diff",
            "load",
        ],
        "toy 12-state loop, RK4: vmap (batch first) vs the same function on (12, B)",
    )
    C.write_json(args.json, args, rows)
    return rows


if __name__ == "__main__":
    main()
