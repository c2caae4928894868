"""XLA's CPU code generator for the ``vcjax`` command line: the faster-compiling one.

XLA compiles every fused kernel of a program separately. Its newer CPU kernel generator
(MLIR-based "fusion emitters", the default since jaxlib 0.6) runs a pass pipeline per kernel
whose set-up dominates the compile of a closed loop, whose rollouts are thousands of small
scalar kernels; the older generator (``--xla_cpu_use_fusion_emitters=false``) builds the same
kernels in about half the time. Measured on the 2-core development machine (same run, fresh
processes, a loaded machine; ``docs/performance.md``): REMUS 100's 250-step gradient compiles
in half the time and runs faster; the INFANTE-class batch gradient of 1024 compiles 25 % faster
and runs 4-6 % slower; the batched sweeps of ``benchmarks/before_after.py --cli-compiler`` are
no slower than before this round.

[`prefer_fast_compile`][vcjax.runtime.compiler.prefer_fast_compile] (called once at the start of
``vcjax.cli.main``, before JAX
creates its backend) adds that flag to ``XLA_FLAGS`` unless

* ``XLA_FLAGS`` already says ``--xla_cpu_use_fusion_emitters=...`` (yours wins), or
* ``VCJAX_FAST_COMPILE`` is ``0``, ``off``, ``false`` or ``no``, or
* the installed jaxlib predates the flag (before 0.6: an unknown XLA flag aborts the process)
  or is newer than the newest release it was checked with (``CHECKED``): XLA may retire a
  flag, and an unknown flag aborts the process, so an untested jaxlib gets XLA's default.

The library itself never sets it on import (``import vcjax`` changes no JAX or XLA setting).
It asks for the same generator **per program** instead: every program vcjax compiles itself
(a sweep's batch, the tuner's steps, the falsify search, the fit's residuals, the presets'
rollouts, the program store's) is compiled with the XLA option
``xla_cpu_use_fusion_emitters=False`` ([`compile_options`][vcjax.runtime.compiler.compile_options],
through [`jit`][vcjax.runtime.compiler.jit]), which changes nothing else in the process. The same
exceptions apply, and a program compiled for another backend than the CPU gets no option.

A Python program or notebook that jits its own functions (``jax.jit(jax.grad(loss))`` around
``loops.simulate``) gets XLA's default for them. Two ways to the faster generator:

* [`vcjax.jit`][vcjax.runtime.compiler.jit] in place of ``jax.jit``: the same arguments, the
  option for that program; usable at any time;
* [`vcjax.fast_compile`][vcjax.runtime.compiler.fast_compile], once, before the first JAX
  computation: ``XLA_FLAGS`` for every program of the process (JAX's own included), or
  exporting ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=false`` before it starts.

JAX's persistent compilation cache keys its entries by the compile options and ``XLA_FLAGS``,
so programs compiled either way never mix.

**Light programs.** A program that runs once, on little data, is compiled with LLVM's
optimisation level 1 instead of XLA's default 3 (``jit(..., light=True)``, the option
``LIGHT``): the scenario sampler of a sweep
([`sample_scenarios`][vcjax.sweep.spec.sample_scenarios]) compiles in a fifth of the CPU time
(0.35 CPU-s instead of 1.7, REMUS 100's) and draws the same scenarios bit for bit (checked on
every example sweep, float32 and float64, both kernel generators:
``tests/test_compiler.py``); the samples of the path check
([`validate_path`][vcjax.paths.validate_path]) feed that check alone. Only where vcjax chooses:
on the CPU, unless ``XLA_FLAGS`` sets ``--xla_backend_optimization_level`` (yours wins),
``VCJAX_FAST_COMPILE`` is off, or the jaxlib is newer than ``CHECKED``. The closed loops'
programs keep XLA's level: at level 1 their last bits move (XLA's fused kernels evaluate
sines, cosines and multiply-adds differently).
"""

from __future__ import annotations

import functools
import os
import threading

__all__ = [
    "ENV",
    "FLAG",
    "OPTION",
    "CHECKED",
    "LIGHT",
    "BackendStartedError",
    "compile_options",
    "fast_compile",
    "jit",
    "light_options",
    "prefer_fast_compile",
]

ENV = "VCJAX_FAST_COMPILE"
#: the XLA flag (older, faster-compiling CPU kernel generator)
FLAG = "--xla_cpu_use_fusion_emitters=false"
#: the same choice as one program's XLA compile option (``jax.jit(..., compiler_options=...)``)
OPTION = "xla_cpu_use_fusion_emitters"
_OFF = ("0", "off", "false", "no")
_FIRST = (0, 6)  # the first jaxlib whose XLA knows the flag
#: the newest jaxlib (major, minor) the flag was checked with (raise it after checking a newer one)
CHECKED = (0, 10)
#: the compile options of a light program (``jit(..., light=True)``; module docstring)
LIGHT = {"xla_backend_optimization_level": 1}


def jaxlib_version(parts: int = 2, version: str | None = None) -> tuple[int, ...]:
    """The first ``parts`` numbers of ``version`` (default: the installed jaxlib's; ``(0, ...)``
    when none is installed); a part that does not start with a digit counts as 0, trailing
    letters are dropped (``0.7.0rc1`` -> ``(0, 7, 0)``). Imports no JAX."""
    if version is None:
        try:
            import jaxlib

            version = jaxlib.__version__
        except (ImportError, AttributeError):
            return (0,) * parts
    out = []
    for part in (version.split(".") + ["0"] * parts)[:parts]:
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        out.append(int(digits or "0"))
    return tuple(out)


def _jaxlib_version() -> tuple[int, ...]:
    return jaxlib_version(2)


def _wanted(env) -> bool | None:
    """True/False: the faster generator is wanted/refused by ``XLA_FLAGS`` (the user's choice);
    None: ``XLA_FLAGS`` does not say, and vcjax may choose (unless ``VCJAX_FAST_COMPILE`` is off
    or the jaxlib is outside the checked range: then False)."""
    flags = env.get("XLA_FLAGS", "")
    if OPTION in flags:
        return FLAG in flags.split()
    if env.get(ENV, "").strip().lower() in _OFF or not _FIRST <= _jaxlib_version() <= CHECKED:
        return False
    return None


def compile_options(environ=None) -> dict:
    """The XLA compile options vcjax compiles its own programs with: ``{OPTION: False}`` (the
    faster-compiling CPU kernel generator, module docstring) when JAX's default backend is the
    CPU, else ``{}``.

    ``{}`` too where ``XLA_FLAGS`` already chooses ``--xla_cpu_use_fusion_emitters`` (yours
    applies to every program, vcjax's included), where ``VCJAX_FAST_COMPILE`` is
    ``0``/``off``/``false``/``no``, and with a jaxlib the option was not checked with (before 0.6
    XLA refuses it: "No such compile option"). Asking for the default backend starts JAX's
    backend: call it where a program is about to be compiled.
    """
    env = os.environ if environ is None else environ
    if _wanted(env) is not None:
        return {}
    import jax

    return {OPTION: False} if jax.default_backend() == "cpu" else {}


def light_options(environ=None) -> dict:
    """What a light program (``jit(..., light=True)``) adds to
    [`compile_options`][vcjax.runtime.compiler.compile_options]: ``LIGHT`` (LLVM's optimisation
    level 1, module docstring) when JAX's default backend is the CPU, else ``{}``; ``{}`` too
    where ``XLA_FLAGS`` sets ``--xla_backend_optimization_level`` (yours wins), where
    ``VCJAX_FAST_COMPILE`` is off, and with a jaxlib newer than ``CHECKED``."""
    env = os.environ if environ is None else environ
    if (
        "xla_backend_optimization_level" in env.get("XLA_FLAGS", "")
        or env.get(ENV, "").strip().lower() in _OFF
        or _jaxlib_version() > CHECKED
    ):
        return {}
    import jax

    return dict(LIGHT) if jax.default_backend() == "cpu" else {}


class _Jit:
    """``jax.jit(fun, **kwargs)`` with [`compile_options`][vcjax.runtime.compiler.compile_options],
    created at the first call or attribute access (``lower``, ``trace``, ``eval_shape``, ...),
    when JAX's backend is known."""

    def __init__(self, fun, kwargs, light: bool = False):
        self._fun, self._kwargs, self._light = fun, kwargs, light
        self._jitted = self._plain = None
        self._lock = threading.Lock()
        functools.update_wrapper(self, fun)

    def _get(self):
        if self._jitted is None:
            import jax

            with self._lock:
                if self._jitted is None:
                    kwargs = dict(self._kwargs)
                    options = compile_options()
                    if self._light:
                        options = {**options, **light_options()}
                    if options:
                        kwargs["compiler_options"] = {
                            **options,
                            **kwargs.get("compiler_options", {}),
                        }
                    self._jitted = jax.jit(self._fun, **kwargs)
        return self._jitted

    def __call__(self, *args, **kwargs):
        jitted = self._get()
        try:
            return jitted(*args, **kwargs)
        except ValueError as err:  # JAX refuses compile options on a jit inside another one
            if "can only be passed to top-level" not in str(err):
                raise
        # called while another program is traced (a user's jax.jit around it): it becomes part
        # of that program, which compiles with that program's options
        if self._plain is None:
            import jax

            plain = {k: v for k, v in self._kwargs.items() if k != "compiler_options"}
            self._plain = jax.jit(self._fun, **plain)
        return self._plain(*args, **kwargs)

    def __getattr__(self, name):
        if name.startswith("__") or name in (
            "_fun",
            "_kwargs",
            "_light",
            "_jitted",
            "_plain",
            "_lock",
        ):
            raise AttributeError(name)
        return getattr(self._get(), name)


def jit(fun=None, *, light: bool = False, **kwargs):
    """``jax.jit`` compiled with XLA's faster-compiling CPU kernel generator: the same arguments
    (``static_argnames``, ``donate_argnums``, ...; usable as a decorator, bare or with arguments),
    plus [`compile_options`][vcjax.runtime.compiler.compile_options] for this program only.

    Use it in place of ``jax.jit`` for your own functions of vcjax's loops (a loss and its
    gradient around ``loops.simulate``): REMUS 100's 250-step gradient compiles in about
    two-thirds of the time (``docs/performance.md``). Unlike
    [`fast_compile`][vcjax.runtime.compiler.fast_compile] it can be called at any time, and
    changes no other program of the process. On GPU or TPU, where ``VCJAX_FAST_COMPILE`` is off,
    or where ``XLA_FLAGS`` already chooses the generator, it is ``jax.jit``. vcjax compiles its
    own programs this way.

    ``light=True``: a program that runs once on little data, compiled with LLVM's optimisation
    level 1 as well (``LIGHT``, module docstring); only for a program whose results you have
    checked to be the same bit for bit (vcjax's scenario sampler) or that feed a check alone
    (vcjax's path check).
    """
    if fun is None:
        return functools.partial(jit, light=light, **kwargs)
    return _Jit(fun, kwargs, light)


def prefer_fast_compile(environ=None) -> bool:
    """Add ``FLAG`` to ``XLA_FLAGS`` of ``environ`` (default ``os.environ``) unless the
    module docstring's exceptions apply; returns whether it is in effect for XLA's CPU
    backend. Call it before the first JAX computation (XLA reads its flags once)."""
    env = os.environ if environ is None else environ
    wanted = _wanted(env)
    if wanted is not None:
        return wanted
    env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {FLAG}".strip()
    return True


class BackendStartedError(RuntimeError):
    """[`fast_compile`][vcjax.runtime.compiler.fast_compile] was called after JAX had started its
    backend (XLA reads its flags
    once, when the first computation creates the backend)."""


def _backend_started() -> bool:
    """Whether JAX has created its XLA backends in this process (False when JAX is not even
    imported; imports nothing)."""
    import sys

    xb = sys.modules.get("jax._src.xla_bridge")
    if xb is None:
        return False
    started = getattr(xb, "backends_are_initialized", None)
    if callable(started):
        try:
            return bool(started())
        except Exception:  # pragma: no cover - a JAX whose private helper changed
            pass
    return bool(getattr(xb, "_backends", None))


def fast_compile() -> bool:
    """Compile faster on CPU: set XLA's older CPU kernel generator for this process, as the
    ``vcjax`` command line does.

    Adds ``--xla_cpu_use_fusion_emitters=false`` to ``os.environ["XLA_FLAGS"]`` (REMUS 100's
    250-step gradient compiles in about half the time; batched runs are a few per cent slower or
    faster, see ``docs/performance.md``). Call it once, at the top of a script or notebook,
    **before the first JAX computation**: XLA reads ``XLA_FLAGS`` once, when JAX starts its
    backend, so a later call could not take effect and raises
    [`BackendStartedError`][vcjax.runtime.compiler.BackendStartedError]
    instead (restart the kernel and call it first). Importing ``vcjax`` or ``jax`` is fine; it is
    the first array, ``jit`` call or ``jax.devices()`` that starts the backend.

    Returns whether the flag is in effect. It is not set (returns False) when ``XLA_FLAGS``
    already chooses ``--xla_cpu_use_fusion_emitters`` (yours wins; True if you chose ``false``),
    when ``VCJAX_FAST_COMPILE`` is ``0``/``off``/``false``/``no``, or when the installed jaxlib
    is one the flag was not checked with (an unknown XLA flag aborts the process). JAX's
    persistent compilation cache keys its entries by the flags, so programs compiled with and
    without it never mix. GPU and TPU compiles are unaffected.
    """
    if _backend_started():
        raise BackendStartedError(
            "vcjax.fast_compile(): JAX has already started its backend, so XLA has read its "
            "flags; call vcjax.fast_compile() before the first JAX computation (restart the "
            "Python process or notebook kernel and call it first)"
        )
    return prefer_fast_compile()
