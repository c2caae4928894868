"""Several processes, one computation: starting them, joining them, and sharding a batch over all
of their devices.

JAX runs one *controller* per process (``jax.distributed.initialize``); every process runs the
same program, owns its local devices, and the devices of all processes form one global mesh.
vcjax uses it two ways:

* **Independent shares** (sweeps): process ``p`` of ``P`` runs its share of the chunks on its
  local devices; no arrays cross processes; process 0 merges the parts (``vcjax.sweep``).
* **One sharded batch** (tuning): the scenario batch of a loss is placed along a global 1-D mesh
  of every process's devices ([`global_mesh`][vcjax.runtime.distributed.global_mesh],
  [`shard_batch`][vcjax.runtime.distributed.shard_batch]); the jitted loss and its
  gradient then reduce across processes (CPU: gloo collectives), and every process gets the
  same, replicated value -- equal to the single-process one.

Starting processes: [`spawn`][vcjax.runtime.distributed.spawn] starts ``n`` local processes with the
coordinator address,
process count and id in the environment (``ENV_COORDINATOR``, ``ENV_NUM_PROCESSES``,
``ENV_PROCESS_ID``); [`initialize_from_env`][vcjax.runtime.distributed.initialize_from_env], called
first thing by the ``vcjax`` CLI,
joins them. Under SLURM (``srun``),
[`initialize_from_env`][vcjax.runtime.distributed.initialize_from_env] uses JAX's cluster
auto-detection instead, so the same command line works there (``vcjax launch`` spawns nothing
inside an ``srun`` step).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from collections.abc import Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vcjax.runtime.interrupts import stop_requested

__all__ = [
    "ENV_COORDINATOR",
    "ENV_NUM_PROCESSES",
    "ENV_PROCESS_ID",
    "in_slurm_step",
    "initialize_from_env",
    "joined",
    "process_index",
    "warm_up",
    "free_port",
    "spawn",
    "global_mesh",
    "shard_batch",
    "replicate",
]

#: ``host:port`` of process 0's coordination service.
ENV_COORDINATOR = "VCJAX_COORDINATOR"
#: number of processes.
ENV_NUM_PROCESSES = "VCJAX_NUM_PROCESSES"
#: this process's id, ``0 <= id < number of processes``.
ENV_PROCESS_ID = "VCJAX_PROCESS_ID"

_initialized = False


def in_slurm_step(environ=None) -> bool:
    """Whether this process is a task of a SLURM job step (started by ``srun``) with more than
    one task -- where ``jax.distributed.initialize()`` finds everything by itself."""
    env = os.environ if environ is None else environ
    return "SLURM_STEP_ID" in env and "SLURM_PROCID" in env and int(env.get("SLURM_NTASKS", 1)) > 1


def _env_triplet(env) -> tuple[str, int, int] | None:
    keys = (ENV_COORDINATOR, ENV_NUM_PROCESSES, ENV_PROCESS_ID)
    present = [k for k in keys if env.get(k)]
    if not present:
        return None
    if len(present) != 3:
        missing = sorted(set(keys) - set(present))
        raise ValueError(f"distributed run: {', '.join(missing)} not set (set all three or none)")
    try:
        n, i = int(env[ENV_NUM_PROCESSES]), int(env[ENV_PROCESS_ID])
    except ValueError:
        raise ValueError(
            f"distributed run: {ENV_NUM_PROCESSES} and {ENV_PROCESS_ID} must be integers"
        ) from None
    if not (n >= 1 and 0 <= i < n):
        raise ValueError(f"distributed run: need 0 <= {ENV_PROCESS_ID} < {ENV_NUM_PROCESSES} = {n}")
    return env[ENV_COORDINATOR], n, i


def initialize_from_env(environ=None, timeout_s: int = 120) -> bool:
    """Join a multi-process run if this process was started as part of one; else do nothing.

    With ``ENV_COORDINATOR``, ``ENV_NUM_PROCESSES`` and ``ENV_PROCESS_ID`` set (as
    [`spawn`][vcjax.runtime.distributed.spawn] sets them) this calls
    ``jax.distributed.initialize(address, n, id)``; inside a
    multi-task SLURM step, ``jax.distributed.initialize()`` (auto-detection). CPU collectives
    use gloo (the default from jax 0.5.1; set explicitly so older settings cannot pick the
    unimplemented one). Must run before any JAX computation. Returns whether it joined a run.
    """
    global _initialized
    env = os.environ if environ is None else environ
    triplet = _env_triplet(env)
    if _initialized or (triplet is None and not in_slurm_step(env)):
        return _initialized
    try:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    except (AttributeError, KeyError, ValueError):  # pragma: no cover - very old/new jax
        pass
    if triplet is None:
        jax.distributed.initialize(initialization_timeout=timeout_s)
    else:
        addr, n, i = triplet
        jax.distributed.initialize(addr, n, i, initialization_timeout=timeout_s)
    _initialized = True
    return True


def process_index() -> int:
    """This process's rank: ``jax.process_index()`` in a run
    [`initialize_from_env`][vcjax.runtime.distributed.initialize_from_env] joined,
    else 0 (no environment variable is read: ``SLURM_PROCID`` set outside a real step, or a
    ``VCJAX_PROCESS_ID`` without its coordinator, does not make a rank)."""
    return int(jax.process_index()) if _initialized else 0


def joined() -> bool:
    """Whether [`initialize_from_env`][vcjax.runtime.distributed.initialize_from_env] joined this
    process to a multi-process run."""
    return _initialized


def warm_up() -> None:
    """Set up the cross-process collectives now, while the processes are in step.

    The CPU collectives (gloo) build their context at the first cross-process operation and give
    up if a peer is not there within 30 s; processes that compile at different speeds (a loaded
    machine) can drift further apart than that before their first collective. Built early, the
    context then waits for late peers. Call it once after the device setup (it starts the JAX
    backend); a no-op outside a multi-process run.
    """
    if not _initialized:
        return
    from jax.experimental import multihost_utils

    multihost_utils.sync_global_devices("vcjax.runtime.distributed: joined")


def free_port(host: str = "localhost") -> int:
    """A TCP port that was free on ``host`` a moment ago (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def spawn(
    n: int,
    argv: Sequence[str],
    *,
    port: int | None = None,
    cpu_devices: int | None = None,
    env: dict | None = None,
    timeout_s: float | None = None,
    stdout=None,
    stderr=None,
) -> list[int]:
    """Run ``argv`` as ``n`` local processes of one JAX distributed run and wait for them.

    Process ``i`` gets ``ENV_COORDINATOR`` = ``localhost:port`` (a free port unless given),
    ``ENV_NUM_PROCESSES`` = ``n`` and ``ENV_PROCESS_ID`` = ``i`` on top of ``env``
    (default: this process's environment); with ``cpu_devices`` each process splits the host CPU
    into that many devices (``VCJAX_CPU_DEVICES``, read by the ``vcjax`` commands, and
    ``XLA_FLAGS=--xla_force_host_platform_device_count`` for any other JAX program). If one
    process fails, or ``timeout_s`` passes, the others are terminated. Called inside
    ``interrupt_guard``, an interrupt is forwarded to the processes
    (SIGINT) and they are waited for: each keeps and writes what it has done.

    Returns:
        the ``n`` exit codes (``-SIGTERM``'s value for a terminated process).
    """
    if int(n) < 1:
        raise ValueError(f"n: expected >= 1 processes, got {n!r}")
    if not argv:
        raise ValueError("argv: nothing to run")
    if cpu_devices is not None and int(cpu_devices) < 1:
        raise ValueError(f"cpu_devices: expected >= 1, got {cpu_devices!r}")
    port = free_port() if port is None else int(port)
    base = dict(os.environ if env is None else env)
    if cpu_devices is not None:
        flags = [f for f in base.get("XLA_FLAGS", "").split() if "device_count" not in f]
        flags.append(f"--xla_force_host_platform_device_count={int(cpu_devices)}")
        base["XLA_FLAGS"] = " ".join(flags)
        base["VCJAX_CPU_DEVICES"] = str(int(cpu_devices))
    procs = []
    for i in range(int(n)):
        e = dict(base)
        e.update(
            {
                ENV_COORDINATOR: f"localhost:{port}",
                ENV_NUM_PROCESSES: str(int(n)),
                ENV_PROCESS_ID: str(i),
            }
        )
        procs.append(subprocess.Popen(list(argv), env=e, stdout=stdout, stderr=stderr))
    deadline = None if timeout_s is None else time.monotonic() + float(timeout_s)
    codes: list[int | None] = [None] * len(procs)
    forwarded = False
    try:
        while any(c is None for c in codes):
            for k, p in enumerate(procs):
                if codes[k] is None:
                    codes[k] = p.poll()
            if stop_requested() and not forwarded:  # interrupted (runtime.outputs): pass it on
                forwarded = True
                for k, p in enumerate(procs):
                    if codes[k] is None:
                        p.send_signal(signal.SIGINT)
            failed = any(c not in (None, 0) for c in codes)
            late = deadline is not None and time.monotonic() > deadline
            if failed or late:
                break
            time.sleep(0.05)
    finally:
        for k, p in enumerate(procs):
            if codes[k] is None:
                p.send_signal(signal.SIGTERM)
        for k, p in enumerate(procs):
            try:
                codes[k] = p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                codes[k] = p.wait()
    return [int(c) for c in codes]


def global_mesh(axis: str = "batch") -> Mesh:
    """A 1-D mesh over every device of every process (``jax.devices()``), axis named ``axis``."""
    return Mesh(np.asarray(jax.devices()), (axis,))


def shard_batch(tree, mesh: Mesh, axes=0):
    """Place a batch along ``mesh``'s (single) axis; what is not batched is replicated.

    Every process passes the *same* full batch (e.g. sampled from the same seed); each keeps only
    the rows of its own devices. ``axes`` is a prefix of ``tree`` like ``jax.vmap``'s
    ``in_axes``: ``0`` for leaves batched along their leading axis, ``None`` for shared ones.
    The batch size ``B`` must be a multiple of the mesh size (a padded row would change a mean
    or a CVaR). Returns global ``jax.Array``s.
    """
    (name,) = mesh.axis_names
    size = mesh.devices.size
    pairs = []

    def collect(ax, sub):
        if ax not in (0, None):
            raise ValueError(f"shard_batch: axes must be 0 or None, got {ax!r}")
        pairs.append((ax, sub))

    jax.tree_util.tree_map(collect, axes, tree, is_leaf=lambda x: x is None)
    sizes = {
        np.shape(x)[0] if np.ndim(x) else None
        for ax, sub in pairs
        if ax == 0
        for x in jax.tree_util.tree_leaves(sub)
    }
    if len(sizes) != 1 or None in sizes:
        raise ValueError(f"shard_batch: batched leaves need one leading axis, got {sizes}")
    (b,) = sizes
    if b % size:
        raise ValueError(
            f"shard_batch: batch of {b} does not split over {size} devices; use a multiple of "
            f"{size}"
        )

    def put(ax, sub):
        spec = (lambda x: PartitionSpec(name, *([None] * (x.ndim - 1)))) if ax == 0 else None
        return _put(sub, mesh, spec)

    return jax.tree_util.tree_map(put, axes, tree, is_leaf=lambda x: x is None)


def _put(tree, mesh: Mesh, spec=None):
    """Global arrays from a process-local full copy; ``spec(x)`` the partition (None: replicate)."""

    def one(x):
        x = np.asarray(x)
        sh = NamedSharding(mesh, PartitionSpec() if spec is None else spec(x))
        return jax.make_array_from_callback(x.shape, sh, lambda idx: x[idx])

    return jax.tree_util.tree_map(one, tree)


def replicate(tree, mesh: Mesh):
    """Every leaf as a global array replicated on every device of ``mesh`` (the same value is
    expected in every process)."""
    return _put(tree, mesh)
