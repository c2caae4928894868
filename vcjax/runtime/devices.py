"""How many JAX devices the host CPU is split into (set once, before JAX initialises).

On a CPU, JAX sees one device by default, and a ``vmap``-ed batch on one device runs on one
core (XLA's CPU backend does not spread elementwise loops over threads). Splitting the host into
as many CPU devices as cores and sharding the batch axis over them (as [`vcjax.sweep`][vcjax.sweep]
does
over its local devices) keeps every core busy. The split is a process-wide JAX setting
(``jax_num_cpu_devices``) that must be made before the first JAX computation, so command-line
entry points call [`use_cpu_cores`][vcjax.runtime.devices.use_cpu_cores] first thing; a library call
never changes it for you.

Which count, first match wins:

1. the explicit argument (``vcjax sweep/tune --cpu-devices N``);
2. the environment variable ``VCJAX_CPU_DEVICES``;
3. nothing, if ``XLA_FLAGS`` already sets ``--xla_force_host_platform_device_count`` (yours);
4. the number of cores this process may run on (``os.sched_getaffinity``).

``1`` means one device, no sharding. On a machine with an accelerator the split only concerns
the CPU backend; sweeps run on the accelerator's devices as before.
"""

from __future__ import annotations

import os

__all__ = ["ENV_VAR", "backend_error", "usable_cores", "cpu_device_count", "use_cpu_cores"]

#: Environment variable that sets the number of host CPU devices.
ENV_VAR = "VCJAX_CPU_DEVICES"
_XLA_FLAG = "--xla_force_host_platform_device_count"


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity; ``os.cpu_count()`` where unknown)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _positive_int(name: str, value) -> int:
    try:
        n = int(str(value).strip())
    except ValueError:
        n = 0
    if n < 1 or str(value).strip() not in (str(n), f"+{n}"):
        raise ValueError(f"{name}: expected a positive integer (CPU devices), got {value!r}")
    return n


def cpu_device_count(n=None, environ=None) -> int | None:
    """The requested number of host CPU devices, or ``None`` to leave JAX's setting alone.

    Args:
        n: explicit count (e.g. from ``--cpu-devices``), or ``None``.
        environ: the environment to read (default ``os.environ``).

    Raises:
        ValueError: naming ``--cpu-devices`` or ``VCJAX_CPU_DEVICES`` for a non-positive or
            non-integer value.
    """
    env = os.environ if environ is None else environ
    if n is not None:
        return _positive_int("--cpu-devices", n)
    if env.get(ENV_VAR, "").strip():
        return _positive_int(ENV_VAR, env[ENV_VAR])
    if _XLA_FLAG in env.get("XLA_FLAGS", ""):
        return None
    return usable_cores()


def _backends_initialised() -> bool:
    """Whether JAX has created its backends (then the CPU device count is fixed). Uses JAX's
    private ``xla_bridge.backends_are_initialized`` where it exists (jax 0.5.1 and later)."""
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - a JAX without that module
        return False
    check = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(check()) if check is not None else False


def use_cpu_cores(n=None) -> int | None:
    """Split the host CPU into [`cpu_device_count`][vcjax.runtime.devices.cpu_device_count] JAX
    devices; return that count.

    Call it before any JAX computation (``import jax`` is fine; creating an array is not).
    Returns ``None`` when the count is left to ``XLA_FLAGS``.

    Raises:
        ValueError: for a bad count (see
            [`cpu_device_count`][vcjax.runtime.devices.cpu_device_count]), or when JAX has already
            initialised its CPU backend with a different number of devices and the count was
            asked for explicitly (argument or environment variable); the default (one device
            per core) then quietly keeps the devices JAX already has.
    """
    explicit = n is not None or bool(os.environ.get(ENV_VAR, "").strip())
    count = cpu_device_count(n)
    if count is None:
        return None
    import jax

    try:
        if _backends_initialised():  # jax < 0.6 accepts the update silently, without effect
            raise RuntimeError("JAX is already running")
        jax.config.update("jax_num_cpu_devices", count)
    except RuntimeError:
        have = len(jax.devices("cpu"))
        if have != count and not explicit:
            return have  # the default, asked for too late (JAX already running): keep what runs
        if have != count:
            raise ValueError(
                f"--cpu-devices: JAX is already running with {have} CPU device(s); "
                f"the count ({count}) must be set before the first JAX computation"
            ) from None
    return count


def backend_error() -> str | None:
    """Why JAX's backend cannot start here (one line), or None if it can.

    For the CLI after a command failed: a platform asked for that this machine lacks
    (``JAX_PLATFORMS=cuda`` on a CPU-only machine) surfaces inside JAX as a bare
    ``AssertionError``; this names the setting instead. Starts the backend if it was not."""
    import jax

    try:
        jax.devices()
    except Exception as err:  # noqa: BLE001 - whatever the backend raised, said in one line
        asked = os.environ.get("JAX_PLATFORMS") or jax.config.jax_platforms
        why = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        if asked:
            return (
                f"JAX_PLATFORMS={asked}: JAX cannot start that platform on this machine ({why}); "
                "unset JAX_PLATFORMS, or set it to a platform this machine has (cpu)"
            )
        return f"JAX cannot start its backend: {why}"
    return None
