"""Shared helpers of the benchmark scripts: dtype switch, timing, scenarios, tables, JSON.

The dtype must be chosen before any JAX array exists (``jax_enable_x64`` is process-global), so
the scripts parse their arguments, call :func:`setup`, and only then import vcjax (vcjax builds
Simulation 1's path coefficients at import time).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

VARIANT = "vcm_integral"
DT = 0.05


def add_common_args(p: argparse.ArgumentParser, dtype="float32") -> None:
    p.add_argument("--dtype", choices=("float32", "float64"), default=dtype)
    p.add_argument("--repeats", type=int, default=3, help="timed repeats (best is reported)")
    p.add_argument("--json", type=Path, default=None, help="write the rows to this JSON file")
    p.add_argument("--quick", action="store_true", help="smoke run: small sizes, 2 repeats")


def setup(dtype: str, cpu_devices: int | None = None) -> None:
    """Enable x64 when float64 is requested (the library never does it itself); with
    ``cpu_devices``, split the host CPU into that many JAX devices first (before JAX starts)."""
    import jax

    if cpu_devices is not None:
        from vcjax.runtime.devices import use_cpu_cores

        use_cpu_cores(cpu_devices)
    if dtype == "float64":
        jax.config.update("jax_enable_x64", True)


def device_str() -> str:
    import jax

    d = jax.devices()[0]
    return f"{d.platform}:{d.device_kind} ({os.cpu_count()} cores)"


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else the machine type."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def meta(args) -> dict:
    import jax

    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "jax": jax.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "device": device_str(),
        "cpu": platform.processor() or platform.machine(),
        "cpu_model": cpu_model(),
        "load_average_1min_at_end": load_average(),
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
    }


def block(x):
    import jax

    return jax.block_until_ready(x)


def best_of(fn, repeats: int, warmup: int = 1) -> float:
    """Best wall time [s] of ``fn()`` over ``repeats`` calls, after ``warmup`` untimed calls.

    The process CPU time of that best call is kept in :data:`LAST_CPU_S` (all threads): with
    other jobs on the machine, ``cpu / wall`` shows how much of the machine this run had.
    """
    global LAST_CPU_S
    for _ in range(warmup):
        block(fn())
    best, best_cpu = float("inf"), float("nan")
    for _ in range(max(1, repeats)):
        c = time.process_time()
        t = time.perf_counter()
        block(fn())
        wall = time.perf_counter() - t
        if wall < best:
            best, best_cpu = wall, time.process_time() - c
    LAST_CPU_S = best_cpu
    return best


LAST_CPU_S = float("nan")


def load_average() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def compile_timed(jitted, *args):
    """``(lower_s, compile_s, compiled)``: trace+lower and XLA compile timed separately."""
    t0 = time.perf_counter()
    lowered = jitted.lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1, compiled


def cost(compiled) -> dict:
    ca = compiled.cost_analysis()
    if isinstance(ca, list | tuple):
        ca = ca[0] if ca else {}
    return dict(ca or {})


def memory(compiled) -> dict:
    m = compiled.memory_analysis()
    keys = ("argument_size_in_bytes", "output_size_in_bytes", "temp_size_in_bytes")
    out = {k.replace("_size_in_bytes", "_bytes"): int(getattr(m, k)) for k in keys}
    alias = int(getattr(m, "alias_size_in_bytes", 0))
    out["alias_bytes"] = alias
    out["peak_bytes"] = out["argument_bytes"] + out["output_bytes"] + out["temp_bytes"] - alias
    return out


# ------------------------------------------------------------------------ Simulation 1 pieces


def base_inputs():
    """Simulation 1's default gains and scenario, in the process's default float dtype."""
    from vcjax import experiments

    sim1 = experiments.get("sim1")
    return sim1.default_gains(VARIANT), sim1.scenario(VARIANT)


def current_field(sc) -> str:
    """The scenario's current field: ``current`` (3,) NED since the scenario layer (issue 9),
    ``V_c`` (2,) before it (``benchmarks.compare.before_after`` runs older revisions too)."""
    return "current" if "current" in sc._fields else "V_c"


def _batched_fields(sc) -> tuple[str, ...]:
    extra = ("varpi0",) if "varpi0" in sc._fields else ()
    return ("eta0", current_field(sc), *extra)


def scenario_axes(sc):
    """``in_axes`` for a scenario batched along ``eta0`` and the current only (and the particle
    start ``varpi0`` where the scenario carries it)."""
    batched = _batched_fields(sc)
    return type(sc)(**{f: (0 if f in batched else None) for f in sc._fields})


def batched_scenario(sc, batch: int, seed: int = 0):
    """``sc`` with ``eta0`` (B, 3) and the current batched: random initial offsets and currents.

    Offsets: x, y ~ N(0, 5 m), psi ~ N(0, 0.5 rad) around Simulation 1's start; current: random
    direction, magnitude ~ U(0, 0.5) m/s. The particle starts abreast of the vehicle (``w0 = y0``
    on Simulation 1's line ``[10, w]``), as ``sim1`` did before ``varpi0`` became a field.
    """
    import jax.numpy as jnp

    rng = np.random.default_rng(seed)
    dtype = sc.eta0.dtype
    d_eta = rng.normal(size=(batch, 3)) * np.array([5.0, 5.0, 0.5])
    ang = rng.uniform(-np.pi, np.pi, size=batch)
    mag = rng.uniform(0.0, 0.5, size=batch)
    cur = np.stack([mag * np.cos(ang), mag * np.sin(ang), np.zeros(batch)], axis=1)
    eta0 = np.asarray(sc.eta0)[None, :] + d_eta
    name = current_field(sc)
    cur = cur[:, : np.asarray(getattr(sc, name)).shape[-1]]
    out = {"eta0": jnp.asarray(eta0, dtype=dtype), name: jnp.asarray(cur, dtype=dtype)}
    if "varpi0" in sc._fields:
        out["varpi0"] = jnp.asarray(eta0[:, 1], dtype=dtype)
    return sc._replace(**out)


def shard_batch(scb, devices: int):
    """``scb`` with its batched fields sharded over the first ``devices`` JAX devices along the
    scenario axis (unchanged for one device)."""
    if devices <= 1:
        return scb
    import jax
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    mesh = Mesh(np.asarray(jax.devices()[:devices]), ("scenarios",))
    sh = NamedSharding(mesh, PartitionSpec("scenarios"))
    return scb._replace(**{f: jax.device_put(getattr(scb, f), sh) for f in _batched_fields(scb)})


def devices_used(x) -> int:
    """Number of devices an array lives on."""
    return len(x.sharding.device_set)


def metric_fn(
    num_steps: int, checkpoint: bool = False, batched: bool = True, timing: str = "continuous"
):
    """``f(gains, scenario, dt) -> (B,)`` mean |e| over the run (or () when not batched).

    Only this reduced metric leaves the jitted function: XLA drops the unused parts of the
    Trajectory (its while-loop simplifier removes dead loop outputs), so memory is
    O(B N) for the stacked cross-track error instead of O(B N x every recorded signal).
    """
    from vcjax import experiments, loops
    from vcjax.rollout import RolloutConfig

    cfg = RolloutConfig(num_steps=num_steps, integrator="rk4", checkpoint=checkpoint, timing=timing)
    loop = experiments.get("sim1").loop(VARIANT)

    def one(gains, sc, dt):
        tr = loops.simulate(loop, gains, sc, cfg, dt)
        return jnp_mean_abs(tr.aux.eps[:, 1])

    if not batched:
        return one

    def many(gains, sc, dt):
        import jax

        return jax.vmap(one, in_axes=(None, scenario_axes(sc), None))(gains, sc, dt)

    return many


def jnp_mean_abs(x):
    import jax.numpy as jnp

    return jnp.mean(jnp.abs(x))


# ------------------------------------------------------------------------------ reporting


def fmt(v) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        if v == 0:
            return "0"
        a = abs(v)
        if a >= 1e5 or a < 1e-3:
            return f"{v:.3e}"
        return f"{v:.4g}"
    return str(v)


def print_table(rows: list[dict], columns: list[str], title: str = "") -> None:
    if title:
        print(f"\n{title}")
    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [
        max(len(c), *(len(x[i]) for x in cells)) if cells else len(c) for i, c in enumerate(columns)
    ]
    print("| " + " | ".join(c.ljust(w) for c, w in zip(columns, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for x in cells:
        print("| " + " | ".join(v.rjust(w) for v, w in zip(x, widths, strict=True)) + " |")


def write_json(path: Path | None, args, rows: list[dict], **extra) -> None:
    if path is None:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"meta": meta(args), "rows": rows, **extra}
    path.write_text(json.dumps(doc, indent=2, default=float) + "\n")
    print(f"\nwrote {path}")
