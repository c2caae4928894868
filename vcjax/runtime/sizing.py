"""Work sized before it starts: steps and memory of a sweep or a tuning run estimated from its
configuration, and refused (exit 2, with the estimate and the limit) when they cannot fit.

The checks run after the configuration is parsed and before anything is compiled:

* **Steps per run**: ``horizon / dt`` steps of one rollout, at most
[`MAX_STEPS`][vcjax.runtime.sizing.MAX_STEPS] (10
  million, the limit ``vcjax simulate`` has always had); ``--max-steps N`` raises it.
* **Memory**: an estimate of the peak memory (bytes) compared with ``--max-memory-gb`` (default:
  80 % of this machine's physical memory,
  [`default_memory_limit`][vcjax.runtime.sizing.default_memory_limit]):

  - a sweep keeps per scenario and variant its metrics
  ([`METRIC_FLOATS`][vcjax.runtime.sizing.METRIC_FLOATS] float64 values)
    and ``record_points`` trace samples (cross-track error and position, 3 float32), plus the
    sampled scenario ([`SCENARIO_FLOATS`][vcjax.runtime.sizing.SCENARIO_FLOATS] float64), all on the
    host until the end; on the
    device one chunk of ``chunk_size`` scenarios holds one segment of the streamed record
    ([`vcjax.sweep.run.segment_length`][vcjax.sweep.run.segment_length] steps of
    [`STATE_FLOATS`][vcjax.runtime.sizing.STATE_FLOATS] float64 each, x 4
    for the integrator's stages and work buffers);
  - a tuning run in reverse mode keeps the gradient tape: for each of the ``train.size``
    scenarios every step's state at every RK4 stage (``4 x STATE_FLOATS`` float64), or with
    ``checkpoint = true`` the checkpoints plus one recomputed segment (``N / c + c`` steps of
    ``c = checkpoint_every``); forward mode keeps one tangent per tuned gain instead of a tape.

  - a sea (``[waves]``, ``components = N``) adds per scenario its ``N`` components (5 float64
    arrays: frequency, amplitude, wavenumber, phase, direction;
    [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea]) and,
    while the kinematics are evaluated at the vehicle's position,
    [`WAVE_WORK_ARRAYS`][vcjax.runtime.sizing.WAVE_WORK_ARRAYS] more
    ``(N,)`` arrays per scenario of a chunk (phases, attenuation, the sines and cosines and the
    per-component terms of the velocity and acceleration); a reverse-mode tuning run keeps
    [`WAVE_TAPE_ARRAYS`][vcjax.runtime.sizing.WAVE_TAPE_ARRAYS] of them per scenario, step and RK4
    stage on its tape. 10 million
    components x 256 scenarios: one such array is 20 GB, the whole 410 GB.

  [`STATE_FLOATS`][vcjax.runtime.sizing.STATE_FLOATS] (64) is an upper estimate of what one step
  records for the built-in
  loops (state, controller state, controller outputs and diagnostics; the 6-DOF REMUS 100 loop
  is the largest, at about 50). The estimate is an order-of-magnitude guard against work that
  cannot fit (``num_scenarios = 1e9``, ``horizon = 1e9``), not a measurement.
* **Wall time of a sea** (a warning, not a refusal;
[`time_warnings`][vcjax.runtime.sizing.time_warnings]): the kinematics cost
  about [`WAVE_SECONDS_PER_COMPONENT`][vcjax.runtime.sizing.WAVE_SECONDS_PER_COMPONENT] per
  component and RK4 stage, four stages per step;
  above [`WALL_WARN_S`][vcjax.runtime.sizing.WALL_WARN_S] seconds of it the command says so (with
  the estimate) before it
  starts.
* **Fit**: the multiple-shooting residuals and Jacobians of ``vcjax fit``
  (``fit_estimate``), against the same memory limit.
* **Seeds**: ``jax.random.PRNGKey`` takes integers of the default integer type: seeds must lie
  in ``0 .. 2**63 - 1`` in float64 mode and ``0 .. 2**31 - 1`` with ``--no-x64``
  ([`check_seed`][vcjax.runtime.sizing.check_seed]).
* **vcjax launch**: ``-n`` at most the number of usable cores (and at least 2 are always
  allowed) unless ``--max-processes`` allows more; ``--timeout`` must be positive
  ([`check_launch`][vcjax.runtime.sizing.check_launch]).
"""

from __future__ import annotations

import math
import os
import sys

__all__ = [
    "MAX_STEPS",
    "STATE_FLOATS",
    "SizeError",
    "Estimate",
    "check_launch",
    "check_seed",
    "default_memory_limit",
    "sweep_estimate",
    "tune_estimate",
    "fit_estimate",
    "check_estimate",
    "time_warnings",
    "WAVE_WORK_ARRAYS",
    "WAVE_TAPE_ARRAYS",
    "WAVE_SECONDS_PER_COMPONENT",
    "WALL_WARN_S",
]

#: Default limit of steps per rollout (``--max-steps``).
MAX_STEPS = 10_000_000
#: Floats recorded per step and scenario (upper estimate for the built-in loops).
STATE_FLOATS = 64
#: Metric values kept per scenario and variant (the metrics, flags and actuator entries).
METRIC_FLOATS = 48
#: Sampled values kept per scenario (initial state, current, model factors, ...).
SCENARIO_FLOATS = 32
#: ``(N,)`` arrays of a sea per scenario: the
#: [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea] itself.
WAVE_SEA_ARRAYS = 5
#: ``(N,)`` work arrays per scenario while a sea's kinematics are evaluated (phase, attenuation,
#: cos, sin, c, s, the convective terms q and A, the acceleration's sums, the sampler's draws).
#: Measured: a REMUS 100 sweep's peak resident memory grows by 159 bytes (20 float64) per
#: component and scenario of a chunk (16 scenarios, 4e5 and 8e5 components: +1.05 and +2.06 GB
#: over 64 components), i.e. the sea's 5 arrays and 15 more.
WAVE_WORK_ARRAYS = 15
#: ``(N,)`` arrays per scenario, step and RK4 stage a reverse-mode gradient keeps of a sea
#: (the attenuated amplitude, cos and sin of the phase, q and A).
WAVE_TAPE_ARRAYS = 5
#: Seconds per sea component and RK4 stage of one scenario (float64, XLA:CPU, 2 cores): 24 ns
#: with 1e6 components (77 s for 800 scenario-steps) and ~35 ns with 8e5 (a loaded machine),
#: memory-bound; 64 components in cache cost ~5 ns (float32,
#: ``benchmarks/results/waves_cost.json``). 20 ns: a low large-N figure (the warning's estimate
#: errs short), where the warning matters.
WAVE_SECONDS_PER_COMPONENT = 20e-9
#: A sea whose kinematics alone are estimated above this many seconds is warned about.
WALL_WARN_S = 60.0
_F64 = 8
_F32 = 4


class SizeError(ValueError):
    """Work that is refused before it starts (the CLI prints it as one line, exit code 2)."""


def default_memory_limit() -> float:
    """80 % of the physical memory [bytes] (``os.sysconf``; 16 GiB where it is unknown)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        total = 20 * 2**30
    return 0.8 * float(total)


class Estimate(dict):
    """``steps_per_run``, ``runs``, ``trajectory_steps``, ``memory_bytes``, ``parts`` (the
    named terms of the memory estimate) and ``wave_components`` (0: no sea)."""


def _gb(x: float) -> str:
    return f"{x / 1e9:.3g} GB"


def sweep_estimate(spec) -> Estimate:
    """Steps and memory of a [`SweepSpec`][vcjax.sweep.spec.SweepSpec] (see the module
    docstring)."""
    n_steps = max(1, int(round(spec.horizon / spec.dt)))
    n, v = int(spec.num_scenarios), len(spec.variants)
    points = min(int(spec.record_points), n_steps + 1)
    per_result = METRIC_FLOATS * _F64 + points * 3 * _F32
    host = n * (v * per_result + SCENARIO_FLOATS * _F64)
    stride = 0 if points == 0 else max(1, -(-n_steps // max(points, 1)))
    seg = stride if stride > 0 else min(100, n_steps)
    chunk = min(int(spec.chunk_size), n)
    device = chunk * seg * STATE_FLOATS * _F64 * 4
    parts = {"host results": host, "device chunk": device}
    sc = spec.scenario
    comps = int(sc.waves.components) if sc.waves else 0
    if comps:
        parts["sea"] = chunk * comps * (WAVE_SEA_ARRAYS + WAVE_WORK_ARRAYS) * _F64
    return Estimate(
        steps_per_run=n_steps,
        runs=n * v,
        trajectory_steps=n * v * n_steps,
        memory_bytes=sum(parts.values()),
        parts=parts,
        wave_components=comps,
    )


def tune_estimate(cfg: dict, n_gains: int = 16) -> Estimate:
    """Steps and memory of a validated ``vcjax tune`` config (see the module docstring);
    ``n_gains``: tuned parameters (forward mode)."""
    p = cfg["problem"]
    n_steps = max(1, int(round(p["horizon"] / p["dt"])))
    B, H = int(cfg["train"]["size"]), int(cfg["heldout"]["size"])
    o = cfg["optimizer"]
    per_step = STATE_FLOATS * _F64 * 4
    if o.get("grad_mode", "reverse") == "forward":
        tape = B * per_step * max(1, n_gains)
    elif p.get("checkpoint", True):
        c = max(1, int(p.get("checkpoint_every", 1)))
        tape = B * (n_steps // c + c) * per_step
    else:
        tape = B * n_steps * per_step
    plots = int(cfg.get("report", {}).get("plot_scenarios", 0))
    traj = 2 * min(plots, H) * n_steps * STATE_FLOATS * _F64
    evals = int(o["steps"]) * (1 + int(o.get("max_linesearch_steps", 0)))
    parts = {"gradient tape": tape, "plotted trajectories": traj}
    wav = cfg.get("waves")
    comps = int(wav.get("components", 64)) if wav else 0
    if comps:
        seas = (B + H) * comps * WAVE_SEA_ARRAYS * _F64
        work = max(B, H) * comps * WAVE_WORK_ARRAYS * _F64
        if o.get("grad_mode", "reverse") == "forward":
            work *= 1 + max(1, n_gains)
            kept = 0
        elif p.get("checkpoint", True):
            c = max(1, int(p.get("checkpoint_every", 1)))
            kept = B * c * 4 * comps * WAVE_TAPE_ARRAYS * _F64
        else:
            kept = B * n_steps * 4 * comps * WAVE_TAPE_ARRAYS * _F64
        parts["sea"] = seas + work + kept
    return Estimate(
        steps_per_run=n_steps,
        runs=B * evals + 2 * H,
        trajectory_steps=(B * evals + 2 * H) * n_steps,
        memory_bytes=sum(parts.values()),
        parts=parts,
        wave_components=comps,
    )


def fit_estimate(segments: int, segment_steps: int, n_x: int, n_params: int) -> Estimate:
    """Memory of ``vcjax fit``'s Levenberg–Marquardt: the residuals ``(J, S n_x)`` and the
    Jacobians ``(J, S n_x, p)`` and ``(J, S n_x, n_x)`` in float64, three copies (the current
    and the trial linearisation, and the device buffers)."""
    rows = int(segments) * int(segment_steps) * int(n_x)
    jac = 3 * _F64 * rows * (1 + int(n_params) + int(n_x))
    return Estimate(
        steps_per_run=int(segment_steps),
        runs=int(segments),
        trajectory_steps=int(segments) * int(segment_steps),
        memory_bytes=jac,
        parts={"residuals and Jacobians": jac},
    )


def check_estimate(
    est: Estimate,
    what: str,
    max_steps: int | None = None,
    max_memory_gb: float | None = None,
    notes=(),
) -> None:
    """Raise [`SizeError`][vcjax.runtime.sizing.SizeError] if ``est`` exceeds the step limit
    (default [`MAX_STEPS`][vcjax.runtime.sizing.MAX_STEPS])
    or the memory limit (default
    [`default_memory_limit`][vcjax.runtime.sizing.default_memory_limit]), naming both and the option
    that raises the limit; then print ``notes`` (e.g. the sea's validity,
    [`envelope_warnings`][vcjax.environment.waves.envelope_warnings]) and
    [`time_warnings`][vcjax.runtime.sizing.time_warnings] on stderr, one
    line each, before the run starts."""
    limit_steps = MAX_STEPS if max_steps is None else int(max_steps)
    if est["steps_per_run"] > limit_steps:
        raise SizeError(
            f"{what}: {est['steps_per_run']} steps per run (horizon / dt) exceeds the limit of "
            f"{limit_steps}; use a larger dt or a shorter horizon, or raise the limit with "
            "--max-steps"
        )
    limit = default_memory_limit() if max_memory_gb is None else float(max_memory_gb) * 1e9
    if est["memory_bytes"] > limit:
        parts = ", ".join(f"{k} {_gb(b)}" for k, b in est["parts"].items())
        raise SizeError(
            f"{what}: needs about {_gb(est['memory_bytes'])} of memory ({parts}) but the limit "
            f"is {_gb(limit)}; make the run smaller, or raise the limit with --max-memory-gb"
        )
    for line in [*(f"{what}: {n}" for n in notes), *time_warnings(est, what)]:
        print(f"vcjax: warning: {line}", file=sys.stderr)


def time_warnings(est: Estimate, what: str) -> list[str]:
    """Warnings (one line each) about the wall time of ``est``: a sea whose kinematics alone
    take more than [`WALL_WARN_S`][vcjax.runtime.sizing.WALL_WARN_S] (``trajectory_steps x 4 stages
    x components x``
    [`WAVE_SECONDS_PER_COMPONENT`][vcjax.runtime.sizing.WAVE_SECONDS_PER_COMPONENT])."""
    comps = int(est.get("wave_components", 0))
    if not comps:
        return []
    seconds = est["trajectory_steps"] * 4 * comps * WAVE_SECONDS_PER_COMPONENT
    if seconds <= WALL_WARN_S:
        return []
    return [
        f"{what}: [waves] components = {comps}: the sea's kinematics alone take about "
        f"{_duration(seconds)} ({est['trajectory_steps']} scenario-steps x 4 RK4 stages x "
        f"{comps} components x ~{WAVE_SECONDS_PER_COMPONENT * 1e9:.0f} ns); 64 to 256 components "
        "resolve a spectrum"
    ]


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def check_limits_options(max_steps, max_memory_gb) -> None:
    """``--max-steps`` >= 1 and ``--max-memory-gb`` finite and > 0 (when given)."""
    if max_steps is not None and max_steps < 1:
        raise SizeError(f"--max-steps: expected an integer >= 1, got {max_steps}")
    if max_memory_gb is not None and not (math.isfinite(max_memory_gb) and max_memory_gb > 0):
        raise SizeError(f"--max-memory-gb: expected a finite number > 0, got {max_memory_gb}")


def check_seed(name: str, seed, x64: bool) -> None:
    """Raise [`SizeError`][vcjax.runtime.sizing.SizeError] if ``seed`` is not an integer
    ``jax.random.PRNGKey`` accepts in
    this precision: ``0 .. 2**63 - 1`` (float64 mode) or ``0 .. 2**31 - 1`` (``--no-x64``)."""
    hi = 2**63 - 1 if x64 else 2**31 - 1
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise SizeError(f"{name}: expected an integer seed, got {seed!r}")
    if not 0 <= seed <= hi:
        mode = "float64 mode" if x64 else "--no-x64 (32-bit integers)"
        raise SizeError(f"{name}: {seed} is outside the PRNG's seed range 0 .. {hi} ({mode})")


def check_launch(n, timeout, max_processes, cores: int) -> None:
    """``vcjax launch``: ``1 <= n <= max_processes`` (default: the usable ``cores``, at least 2
    so that a two-process run can always be tried), ``timeout > 0``."""
    if max_processes is not None and max_processes < 1:
        raise SizeError(f"--max-processes: expected an integer >= 1, got {max_processes}")
    bound = max(int(cores), 2) if max_processes is None else max_processes
    if n is not None and n > bound:
        src = "the number of usable CPU cores" if max_processes is None else "--max-processes"
        raise SizeError(
            f"-n {n}: more processes than {src} ({bound}); each is a whole JAX runtime. "
            "Pass --max-processes N to allow more"
        )
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise SizeError(f"--timeout: expected a finite number of seconds > 0, got {timeout:g}")
