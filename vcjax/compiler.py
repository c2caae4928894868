"""XLA's CPU code generator for the ``vcjax`` command line: the faster-compiling one.

XLA compiles every fused kernel of a program separately. Its newer CPU kernel generator
(MLIR-based "fusion emitters", the default since jaxlib 0.6) runs a pass pipeline per kernel
whose set-up dominates the compile of a closed loop, whose rollouts are thousands of small
scalar kernels; the older generator (``--xla_cpu_use_fusion_emitters=false``) builds the same
kernels in about half the time. Measured on the 2-core development machine (same run, fresh
processes; ``docs/performance.md``): REMUS 100's 250-step gradient compiles in half the time
and runs faster; the INFANTE-class batch of 1024 compiles 25 % faster and runs 4-6 % slower.

:func:`prefer_fast_compile` (called once at the start of :func:`vcjax.cli.main`, before JAX
creates its backend) adds that flag to ``XLA_FLAGS`` unless

* ``XLA_FLAGS`` already says ``--xla_cpu_use_fusion_emitters=...`` (yours wins), or
* ``VCJAX_FAST_COMPILE`` is ``0``, ``off``, ``false`` or ``no``, or
* the installed jaxlib predates the flag (before 0.6: an unknown XLA flag aborts the process).

The library itself never sets it (``import vcjax`` changes no JAX or XLA setting); a Python
program gets the same by exporting ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=false`` before
it starts. JAX's persistent compilation cache keys its entries by ``XLA_FLAGS``, so programs
compiled either way never mix.
"""

from __future__ import annotations

import os

__all__ = ["ENV", "FLAG", "prefer_fast_compile"]

ENV = "VCJAX_FAST_COMPILE"
#: the XLA flag (older, faster-compiling CPU kernel generator)
FLAG = "--xla_cpu_use_fusion_emitters=false"
_OFF = ("0", "off", "false", "no")
_FIRST = (0, 6)  # the first jaxlib whose XLA knows the flag


def _jaxlib_version() -> tuple[int, ...]:
    try:
        import jaxlib

        return tuple(int(p) for p in jaxlib.__version__.split(".")[:2])
    except (ImportError, AttributeError, ValueError):
        return (0, 0)


def prefer_fast_compile(environ=None) -> bool:
    """Add :data:`FLAG` to ``XLA_FLAGS`` of ``environ`` (default ``os.environ``) unless the
    module docstring's exceptions apply; returns whether it is in effect for XLA's CPU
    backend. Call it before the first JAX computation (XLA reads its flags once)."""
    env = os.environ if environ is None else environ
    flags = env.get("XLA_FLAGS", "")
    if "xla_cpu_use_fusion_emitters" in flags:
        return FLAG in flags.split()
    if env.get(ENV, "").strip().lower() in _OFF or _jaxlib_version() < _FIRST:
        return False
    env["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
