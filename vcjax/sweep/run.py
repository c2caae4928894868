"""Running a sweep: one scenario ([`simulate_scenario`][vcjax.sweep.run.simulate_scenario],
[`scenario_metrics`][vcjax.sweep.run.scenario_metrics]), a
jitted batch ([`run_batch`][vcjax.sweep.run.run_batch]), a whole study in chunks sharded over
devices and processes
([`run_sweep`][vcjax.sweep.run.run_sweep])."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vcjax import environment, loops
from vcjax.config import ConfigError
from vcjax.loops import DisturbanceParams, Disturbances, gauss_markov_params
from vcjax.metrics import (
    metrics_finalize,
    metrics_init,
    metrics_update,
    run_metrics,
    window_start,
)
from vcjax.rollout import Reduction, RolloutConfig, Trajectory
from vcjax.runtime import compiler, programs
from vcjax.runtime.interrupts import stop_requested
from vcjax.runtime.progress import ProgressBar
from vcjax.sweep.results import SweepResult, run_timing
from vcjax.sweep.spec import MCConfig, MCScenario, SweepSpec, sample_scenarios

__all__ = [
    "nominal",
    "perturb_params",
    "to_scenario",
    "simulate_scenario",
    "scenario_metrics",
    "streamed_metrics",
    "segment_length",
    "run_batch",
    "run_sweep",
    "SCENARIO_FIELDS",
    "SURFACE_METRICS",
    "in_sea",
    "surface_clearance",
    "surface_metrics",
]

#: The sampled fields a [`SweepResult`][vcjax.sweep.results.SweepResult] keeps per scenario (those
#: that are not None: the ``wave_*`` ones only with waves; the sea itself follows from the key).
SCENARIO_FIELDS = tuple(f for f in MCScenario._fields if f not in ("index", "key", "sea"))


def nominal(spec: SweepSpec, dtype=None):
    """``(plant, design, coeffs)`` of a sweep: the vehicle's defaults with the config's
    parameter overrides (``params`` on both, ``plant_params`` on the plant), the path's
    coefficients (as arrays of the parameters' dtype)."""
    loop = spec.loop(spec.variants[0])
    plant, design = spec.choice.nominal(loop, dtype)
    ftype = jnp.asarray(jax.tree_util.tree_leaves(design)[0]).dtype
    floating = lambda a: jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating)
    coeffs = jax.tree_util.tree_map(
        lambda a: jnp.asarray(a, ftype) if floating(a) else a, spec.choice.coeffs()
    )
    return plant, design, coeffs


def perturb_params(nominal_params, fields: tuple[str, ...], factors):
    """Parameters with ``nominal.<fields[j]> * factors[j]`` (pure, traced ``factors``; dotted
    names reach into nested parameter NamedTuples)."""
    return loops.replace_params(
        nominal_params,
        {f: loops.get_param(nominal_params, f) * factors[j] for j, f in enumerate(fields)},
    )


def to_scenario(loop, sc: MCScenario, plant, design, coeffs, config: MCConfig) -> loops.Scenario:
    """The loop's [`Scenario`][vcjax.loops.types.Scenario] of a sampled scenario (pure): the plant
    perturbed by the model factors, the design model nominal, the particle starting at the path
    point nearest to the start, the scenario's sea (if any)."""
    return loops.Scenario(
        eta0=sc.eta0,
        nu0=sc.nu0,
        current=sc.current,
        u_d=sc.u_d,
        varpi0=loops.start_parameter(loop.path, coeffs, loop.position(sc.eta0, design)),
        path=coeffs,
        plant=perturb_params(plant, config.model_fields, sc.model_factors),
        design=design,
        disturbance=sc.disturbance,
        sea=sc.sea,
        origin_depth=sc.wave_origin_depth,
    )


#: the stream of a scenario's key its further environment components are drawn from
_ENVIRONMENT_STREAM = 0x656E76


def with_environment(loop, s: loops.Scenario, key, config: MCConfig) -> loops.Scenario:
    """``s`` with the further environment components of ``config`` (``MCConfig.environment``),
    drawn from the scenario's own ``key`` (a stream of its own: the other draws are unchanged)."""
    if not config.environment:
        return s
    k_env = jax.random.fold_in(key, _ENVIRONMENT_STREAM)
    return s._replace(environment=environment.sample(k_env, dict(config.environment), loop))


def simulate_scenario(
    loop, gains, nominal_params, sc: MCScenario, config: MCConfig, dt, reduction=None
) -> tuple[Trajectory, loops.Scenario]:
    """Closed-loop rollout of one loop on one sampled scenario (pure, not jitted).

    ``loop`` and ``config`` are static; ``gains``, ``nominal_params`` (``(plant, design,
    coeffs)``, see [`nominal`][vcjax.sweep.run.nominal]), ``sc`` and ``dt`` [s] are traced. With a
    constant current
    and no sensor noise this *is* [`vcjax.loops.simulate`][vcjax.loops.disturbances.simulate];
    otherwise the same loop gets a
    Gauss–Markov current and/or measurement noise
    ([`Disturbances`][vcjax.loops.disturbances.Disturbances]). A
    scenario with a sea (``[waves]``) hands it to the loop's plant.

    Returns:
        ``(traj, scenario)``; with a ``reduction`` ([`Reduction`][vcjax.rollout.Reduction], built
        from the scenario by ``reduction(scenario)``) ``((acc, outs), scenario)`` instead.
    """
    plant, design, coeffs = nominal_params
    s = to_scenario(loop, sc, plant, design, coeffs, config)
    rcfg = RolloutConfig(
        num_steps=config.num_steps,
        integrator=config.integrator,
        timing=config.timing,
        checkpoint=config.checkpoint,
    )
    dist = Disturbances(
        gauss_markov=config.current_model == "gauss_markov", sensor_noise=config.sensor_noise
    )
    dp = DisturbanceParams(
        current=gauss_markov_params(s, sc.current_sigma, sc.current_tau, sc.current_max_speed),
        noise_std=sc.noise_std,
        key=sc.key,
    )
    s = with_environment(loop, s, sc.key, config)
    red = None if reduction is None else reduction(s)
    return loops.simulate(loop, gains, s, rcfg, dt, dist, dp, reduction=red), s


#: the metrics of a run in a sea (``[waves]``): the fraction of its steps with the vehicle above
#: the local sea surface, and its least depth below that surface [m] (negative: above it), where
#: the submerged model (no free surface, no loss of buoyancy or fin lift) describes no vehicle
SURFACE_METRICS = ("above_surface_fraction", "min_surface_clearance")


def surface_clearance(s: loops.Scenario, pos, t):
    """(L,) depth of positions ``pos`` (L, 3) [m, NED from the origin] below the local sea
    surface at times ``t`` (L,) [s]: ``origin_depth + z + zeta(t, north, east)``, the depth
    below the mean surface plus the sea's elevation there; negative above the surface."""
    from vcjax.environment import waves

    zeta = jax.vmap(lambda tt, q: waves.elevation(s.sea, tt, q[0], q[1]))(t, pos)
    return s.origin_depth + pos[:, 2] + zeta


def in_sea(s: loops.Scenario) -> bool:
    """Whether the scenario ``s`` runs in a sea (its ``sea`` and ``origin_depth`` given)."""
    return s.sea is not None and s.origin_depth is not None


def _surface_init(dtype):
    return jnp.zeros((), dtype), jnp.asarray(jnp.inf, dtype)


def _surface_update(acc, s: loops.Scenario, pos, t):
    above, least = acc
    c = surface_clearance(s, pos, t)
    return above + jnp.sum((c < 0).astype(above.dtype)), jnp.minimum(least, jnp.min(c))


def _surface_metrics(acc, n: int) -> dict:
    above, least = acc
    return {"above_surface_fraction": above / n, "min_surface_clearance": least}


def surface_metrics(s: loops.Scenario, pos, t) -> dict:
    """``SURFACE_METRICS`` of a whole run in a sea: its positions ``pos`` (N, 3) at times ``t``
    (N,) (what the streamed sweep folds in segment by segment)."""
    acc = _surface_update(_surface_init(pos.dtype), s, pos, t)
    return _surface_metrics(acc, pos.shape[0])


def _traces(sig, idx) -> dict:
    return {
        "e": sig.eps[idx, 1].astype(jnp.float32),
        "xy": sig.pos[idx, :2].astype(jnp.float32),
    }


def scenario_metrics(loop, traj: Trajectory, sc: loops.Scenario, config: MCConfig, diverge_e):
    """Metrics and health flags of one run ([`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]
    over the last
    ``config.tail`` of the run), and the recorded traces, from its whole trajectory.

    Returns:
        ``(metrics, traces)``: ``metrics`` maps names to () arrays; ``traces`` maps ``"e"``
        (P,) and ``"xy"`` (P, 2) to float32 samples at ``config.trace_steps``.
    """
    sig = loop.signals(traj, sc)
    m = run_metrics(sig, traj.finite, traj.t[1] - traj.t[0], 1.0 - config.tail, diverge_e)
    # a state that ran away while staying finite (beyond the rollout's bound) diverged too
    m["diverged"] = m["diverged"] | ~traj.healthy
    if in_sea(sc):  # the samples: the states at the start of each step
        m |= surface_metrics(sc, sig.pos, traj.t[: sig.pos.shape[0]])
    return m, _traces(sig, config.trace_steps)


def segment_length(config: MCConfig) -> int:
    """Steps per streamed segment: the trace stride (one trace sample starts each segment),
    else 100."""
    return config.record_stride if config.record_stride > 0 else min(100, config.num_steps)


def streamed_metrics(loop, gains, nominal_params, sc: MCScenario, config: MCConfig, dt, diverge_e):
    """[`simulate_scenario`][vcjax.sweep.run.simulate_scenario] +
    [`scenario_metrics`][vcjax.sweep.run.scenario_metrics] without the trajectory: the rollout
    folds its record into the metrics' accumulator every
    [`segment_length`][vcjax.sweep.run.segment_length] steps
    ([`vcjax.rollout.rollout_reduce`][vcjax.rollout.rollout_reduce]), so memory does not grow with
    the horizon. Same
    metrics and traces as the two functions (the sums in another order: equal to round-off).
    """
    n = config.num_steps
    k0 = window_start(n, 1.0 - config.tail)
    L = segment_length(config)
    dtype = sc.eta0.dtype

    def reduction(s: loops.Scenario) -> Reduction:
        sea = in_sea(s)

        def update(acc, seg, ks):
            sig = loop.signals(seg, s)
            check_act_names(loop, sig, names)
            acc, healthy, surface = acc
            acc = metrics_update(acc, sig, seg.finite, ks, k0)
            if sea:  # the samples are the states at the start of steps ks
                surface = _surface_update(surface, s, sig.pos, ks.astype(dtype) * dt)
            trace = _traces(sig, 0) if config.record_stride > 0 else None
            return (acc, healthy & seg.healthy, surface), trace

        names = _act_names(loop, gains, s)
        surface0 = _surface_init(dtype) if sea else None
        return Reduction((metrics_init(names, dtype), jnp.array(True), surface0), update, L)

    (acc, healthy, surface), outs = simulate_scenario(
        loop, gains, nominal_params, sc, config, dt, reduction
    )[0]
    m = metrics_finalize(acc, n, k0, dt, diverge_e)
    m["diverged"] = m["diverged"] | ~healthy
    if surface is not None:
        m |= _surface_metrics(surface, n)
    if outs is None:
        z = jnp.zeros((0,), jnp.float32)
        outs = {"e": z, "xy": jnp.zeros((0, 2), jnp.float32)}
    return m, outs


def variant_gains(loops_: dict, gains=None) -> dict:
    """``{variant: gains}`` for a sweep's loops: ``gains`` (one gains NamedTuple) for every
    variant whose law's default gains have its type and structure, a dict's entry for its
    variant, the law's defaults for the rest. Gains of one type given for a variant whose law
    takes another are refused (``ValueError``), never silently replaced."""
    if isinstance(gains, dict):
        unknown = sorted(set(gains) - set(loops_))
        if unknown:
            raise ValueError(f"gains: no variant {unknown} in this sweep ({sorted(loops_)})")
        given = dict(gains)
    else:
        given = {}
    out = {}
    for v, loop in loops_.items():
        default = loop.default_gains()
        g = given.get(v, gains if not isinstance(gains, dict) else None)
        if g is None:
            out[v] = default
            continue
        same = type(g) is type(default) and jax.tree_util.tree_structure(
            g
        ) == jax.tree_util.tree_structure(default)
        if not same and v in given:
            raise ValueError(
                f"gains for variant {v!r}: expected {type(default).__name__}, "
                f"got {type(g).__name__}"
            )
        out[v] = g if same else default
    if (
        gains is not None
        and not isinstance(gains, dict)
        and not any(out[v] is gains for v in loops_)
    ):
        raise ValueError(
            f"gains: {type(gains).__name__} fits none of the variants "
            f"{sorted(loops_)} (each takes its law's own gains type)"
        )
    return out


def _owner(cls: type, name: str) -> type | None:
    """The class of ``cls``'s MRO that defines attribute ``name``."""
    return next((c for c in cls.__mro__ if name in vars(c)), None)


def _declared_act_names(loop) -> tuple[str, ...] | None:
    """``loop.act_signals`` (in the order the traced names come: sorted), where the class that
    declares them defines ``signals`` too, or derives from the one that does; else None."""
    declared = getattr(loop, "act_signals", None)
    if declared is None:
        return None
    by, sig = _owner(type(loop), "act_signals"), _owner(type(loop), "signals")
    if by is None or sig is None or not issubclass(by, sig):
        return None
    return tuple(sorted(declared))


def check_act_names(loop, sig, names) -> None:
    """Raise a ``ValueError`` when ``sig.act`` (a loop's signals) holds other actuator signals
    than ``names`` (a loop's ``act_signals`` that do not match its ``signals``)."""
    if set(sig.act) != set(names):
        raise ValueError(
            f"{type(loop).__name__}.act_signals: declared {sorted(names)}, but its signals "
            f"report {sorted(sig.act)}"
        )


def _act_names(loop, gains, s: loops.Scenario) -> tuple[str, ...]:
    """The actuator names of ``loop.signals``: the loop's ``act_signals`` where it declares them
    (see ``_declared_act_names``), else traced abstractly on a one-step record (a trace of the
    controller: a third of REMUS 100's batch program's)."""
    declared = _declared_act_names(loop)
    return _traced_act_names(loop, gains, s) if declared is None else declared


def _traced_act_names(loop, gains, s: loops.Scenario) -> tuple[str, ...]:
    """The actuator names of ``loop.signals``, traced abstractly on a one-step record."""

    def signals():
        x0, z0 = loop.initial_state(s)
        u0, _, aux0 = loop.control(s.eta0[0] * 0, x0, z0, loop.ctrl_params(gains, s))
        rep = lambda tree, k: jax.tree_util.tree_map(lambda a: jnp.stack([a] * k), tree)
        ok = jnp.ones((1,), bool)
        traj = Trajectory(
            rep(s.eta0[0], 2), rep(x0, 2), rep(z0, 2), rep(u0, 1), rep(aux0, 1), ok, ~ok
        )
        return loop.signals(traj, s).act

    return tuple(jax.eval_shape(signals))


@functools.partial(compiler.jit, static_argnames=("loop", "config"))
def _run_batch(loop, gains, nominal_params, scenarios, config, dt, diverge_e):
    def one(sc):
        return streamed_metrics(loop, gains, nominal_params, sc, config, dt, diverge_e)

    return jax.vmap(one)(scenarios)


def _batch_program(loop, config):
    """``_run_batch`` with its static inputs bound (what
    [`programs.build`][vcjax.runtime.programs.build] compiles)."""

    def program(gains, nominal_params, scenarios, dt, diverge_e):
        return _run_batch(loop, gains, nominal_params, scenarios, config, dt, diverge_e)

    return program


def run_batch(loop, gains, nominal_params, scenarios: MCScenario, config: MCConfig, dt, diverge_e):
    """Jitted ``vmap`` of [`simulate_scenario`][vcjax.sweep.run.simulate_scenario] +
    [`scenario_metrics`][vcjax.sweep.run.scenario_metrics] over a batch.

    ``loop`` and ``config`` are static (one compile each); a batch of the same size with new
    values reuses the compiled program (``dt`` [s] and ``diverge_e`` [m] are converted to
    arrays of the parameters' dtype first). If ``scenarios`` is sharded along its batch axis,
    the computation runs sharded and so are the outputs. Returns ``(metrics, traces)`` with a
    leading batch axis.
    """
    dtype = jnp.asarray(jax.tree_util.tree_leaves(nominal_params)[0]).dtype
    dt = jnp.asarray(dt, dtype) if not isinstance(dt, jax.Array) else dt
    diverge_e = jnp.asarray(diverge_e, dtype) if not isinstance(diverge_e, jax.Array) else diverge_e
    return _run_batch(loop, gains, nominal_params, scenarios, config, dt, diverge_e)


def _mesh(devices) -> Mesh:
    return Mesh(np.asarray(devices), ("scenarios",))


def _progress_bar(total: int, progress) -> ProgressBar | None:
    """``progress``: True (bar on stderr), a callable (one line per update) or False."""
    if not progress:
        return None
    sink = progress if callable(progress) else None
    return ProgressBar(total, "sweep ", sink=sink)


class _Parts:
    """What the chunks of a sweep returned, per chunk: scenario numbers, sampled fields, and per
    variant the metrics and traces (the padding dropped)."""

    def __init__(self, variants):
        self.idx, self.sc = [], []
        self.m = {v: [] for v in variants}
        self.tr = {v: [] for v in variants}

    def add_scenarios(self, idx, sc, n_valid: int) -> None:
        self.idx.append(idx[:n_valid])
        host_sc = jax.device_get(sc)
        self.sc.append(
            {
                f: np.asarray(getattr(host_sc, f))[:n_valid]
                for f in SCENARIO_FIELDS
                if getattr(host_sc, f) is not None
            }
        )

    def add(self, v, m, tr, n_valid: int) -> None:
        self.m[v].append({k: np.asarray(a)[:n_valid] for k, a in m.items()})
        self.tr[v].append({k: np.asarray(a)[:n_valid] for k, a in tr.items()})

    def gather(self, spec: SweepSpec):
        """``(index, scenarios, metrics, traces)`` of every chunk, concatenated."""

        def cat(parts, key):
            arrs = [p[key] for p in parts]
            return np.concatenate(arrs) if arrs else np.zeros((0,))

        index = np.concatenate(self.idx) if self.idx else np.zeros(0, dtype=np.int64)
        kept = [f for f in SCENARIO_FIELDS if spec.scenario.waves or not f.startswith("wave_")]
        scenarios = {f: cat(self.sc, f) for f in kept}
        names = {v: list(self.m[v][0]) if self.m[v] else [] for v in spec.variants}
        metrics = {v: {k: cat(self.m[v], k) for k in names[v]} for v in spec.variants}
        traces = {v: {k: cat(self.tr[v], k) for k in ("e", "xy")} for v in spec.variants}
        return index, scenarios, metrics, traces


class _Chunks:
    """A sweep cut into chunks of ``chunk`` scenarios (a multiple of the device count) over
    ``devices``: the placement of batches and of the replicated arguments, each variant's
    program (compiled at the first chunk) and its compile and run times."""

    def __init__(self, spec: SweepSpec, loops_: dict, gains_of: dict, devices: list):
        self.spec, self.loops = spec, loops_
        self.n_dev = n_dev = len(devices)
        chunk = -(-spec.chunk_size // n_dev) * n_dev
        self.chunk = min(chunk, -(-spec.num_scenarios // n_dev) * n_dev)
        self.n_chunks = -(-spec.num_scenarios // self.chunk)
        nom = nominal(spec)
        self.dtype = jnp.asarray(jax.tree_util.tree_leaves(nom[1])[0]).dtype
        self.config = spec.mc_config()
        dt = jnp.asarray(spec.dt, self.dtype)
        diverge_e = jnp.asarray(spec.diverge_e, self.dtype)
        if n_dev == 1 and devices[0] == jax.devices()[0]:
            self.put_batch = put_repl = lambda tree: tree  # no sharding: run_batch's program
            self.batch_sharding = None
        else:
            mesh = _mesh(devices)
            self.batch_sharding = batch_sh = NamedSharding(mesh, PartitionSpec("scenarios"))
            repl = NamedSharding(mesh, PartitionSpec())
            # from the host: split on the device, each field's shape compiled a slicing kernel
            self.put_batch = lambda tree: jax.device_put(jax.device_get(tree), batch_sh)
            put_repl = lambda tree: jax.device_put(tree, repl)
        self.replicated = put_repl((gains_of, nom, dt, diverge_e))
        self.compiled: dict = {}
        self.compile_s = dict.fromkeys(spec.variants, 0.0)
        self.run_s = dict.fromkeys(spec.variants, 0.0)

    def _draw(self, idx) -> MCScenario:
        loop0 = self.loops[self.spec.variants[0]]
        return sample_scenarios(self.spec.scenario, self.spec.seed, idx, self.dtype, loop=loop0)

    def _build(self, idx) -> MCScenario:
        """Every variant's program, built concurrently, once (timed apart), from the batch's
        shapes and placement alone, while the batch ``idx`` is drawn (its sampler compiles
        beside them: one process; several build in the same order, one after another);
        returns the batch."""
        spec = self.spec
        shapes = jax.eval_shape(lambda: self._draw(idx))
        sh = self.batch_sharding  # put_batch places host copies (strong types) there

        def like(a):
            weak = a.weak_type if sh is None else False
            return jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=sh, weak_type=weak)

        batch = jax.tree_util.tree_map(like, shapes)
        gains_d, nom_d, dt_d, div_d = self.replicated
        jobs = [
            (
                f"sweep:{v}",
                _batch_program(self.loops[v], self.config),
                (self.loops[v], self.config),
                (gains_d[v], nom_d, batch, dt_d, div_d),
            )
            for v in spec.variants
        ]
        if jax.process_count() > 1:
            sc, built = self._draw(idx), programs.build_all(jobs)
        else:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(max_workers=1, thread_name_prefix="vcjax-sample") as pool:
                drawn = pool.submit(self._draw, idx)
                built = programs.build_all(jobs)
                sc = drawn.result()
        for v, (call, info) in zip(spec.variants, built, strict=True):
            self.compiled[v], self.compile_s[v] = call, info["build_s"]
        return sc

    def run(self, c: int, parts: _Parts, bar) -> None:
        """Chunk ``c`` (padded with copies of its last scenario) through every variant."""
        spec, chunk = self.spec, self.chunk
        lo = c * chunk
        n_valid = min(chunk, spec.num_scenarios - lo)
        idx = np.arange(lo, lo + chunk)
        idx[n_valid:] = lo + n_valid - 1  # pad with copies of the last scenario
        sc = self._draw(idx) if self.compiled else self._build(idx)
        sc_d = self.put_batch(sc)
        parts.add_scenarios(idx, sc, n_valid)
        gains_d, nom_d, dt_d, div_d = self.replicated
        dyns = {v: (gains_d[v], nom_d, sc_d, dt_d, div_d) for v in spec.variants}
        for v in spec.variants:
            t0 = time.perf_counter()
            m, tr = jax.device_get(self.compiled[v](*dyns[v]))
            self.run_s[v] += time.perf_counter() - t0
            parts.add(v, m, tr, n_valid)
            if bar is not None:
                bar.update(f"chunk {c + 1}/{self.n_chunks} {v}")


def run_sweep(
    spec: SweepSpec,
    gains=None,
    *,
    progress: bool | Callable[[str], Any] = True,
    devices=None,
    process_index: int | None = None,
    process_count: int | None = None,
    stop: Callable[[], bool] | None = None,
) -> SweepResult:
    """Run every variant of ``spec`` on its scenarios, chunk by chunk.

    Chunks hold ``chunk_size`` scenarios rounded up to a multiple of the device count (the last
    chunk is padded with copies of its last scenario, and the copies dropped), so each variant
    compiles once. Each chunk is sharded along the scenario axis over ``devices`` (default: this
    process's local devices; one device: no sharding). With several processes (default:
    ``jax.process_index()`` / ``jax.process_count()``), process ``p`` runs chunks
    ``p, p + P, p + 2P, ...`` on its own devices and returns only those scenarios; combine the
    parts with [`merge_results`][vcjax.sweep.results.merge_results].

    Args:
        spec: the study; gains: the vehicle's gains NamedTuple, used by every variant whose
            law takes gains of that type (the built-in laws of a vehicle share one), or a dict
            ``{variant: gains}``; a variant given no gains runs with its law's defaults (a law
            of your own with gains of its own, swept beside the built-in ones).
        progress: True: a bar on stderr; a callable: receives a line per chunk; False: silent.
        devices: devices to shard over (default ``jax.local_devices()``).
        process_index, process_count: this process's share (default from JAX).
        stop: polled after each chunk; when it returns True the sweep ends there and returns
            the chunks done so far, with ``interrupted = True`` (default:
            ``stop_requested``, set by SIGINT / SIGTERM inside
            ``interrupt_guard``).

    Each variant's program is traced and compiled once, timed apart from running it:
    ``timing`` holds per variant ``compile_s``, ``run_s``
    (executing every chunk and fetching its results, compilation excluded) and
    ``traj_steps_per_s`` (this process's scenarios x steps / ``run_s``).
    """
    t_start = time.perf_counter()
    loops_ = {v: spec.loop(v) for v in spec.variants}
    gains_of = variant_gains(loops_, gains)
    devices = list(jax.local_devices() if devices is None else devices)
    p_idx = jax.process_index() if process_index is None else int(process_index)
    p_cnt = jax.process_count() if process_count is None else int(process_count)
    if not 0 <= p_idx < p_cnt:
        raise ConfigError(f"process_index: expected 0 <= index < {p_cnt}, got {p_idx}")
    r = _Chunks(spec, loops_, gains_of, devices)
    mine = list(range(p_idx, r.n_chunks, p_cnt))
    bar = _progress_bar(len(mine) * len(spec.variants), progress)
    parts = _Parts(spec.variants)
    stop = stop_requested if stop is None else stop
    interrupted = False
    for c in mine:
        if stop():  # a signal arrived: keep the chunks done (at least one, once started)
            interrupted = bool(parts.idx)
            if interrupted:
                break
        r.run(c, parts, bar)
    index, scenarios, metrics, traces = parts.gather(spec)
    n_mine = int(index.size)
    timing = {
        v: run_timing(r.compile_s[v], r.run_s[v], n_mine, r.config.num_steps, r.n_dev)
        for v in spec.variants
    }
    return SweepResult(
        spec=spec,
        index=index,
        scenarios=scenarios,
        metrics=metrics,
        traces=traces,
        trace_t=r.config.trace_steps * spec.dt,
        wall_s=time.perf_counter() - t_start,
        devices=r.n_dev,
        timing=timing,
        interrupted=interrupted,
    )
