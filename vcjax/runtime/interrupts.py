"""Interrupts that keep what is done.

``interrupt_guard``: SIGINT and SIGTERM set a flag (``stop_requested``) that the long
loops poll at safe points (after a sweep chunk, a tuning step, a fit iteration); they stop there
and write what is done, marked ``interrupted``. The CLI then prints one line and exits with
[`EXIT_INTERRUPTED`][vcjax.runtime.interrupts.EXIT_INTERRUPTED] (130). A second signal more than
[`SAME_INTERRUPT_S`][vcjax.runtime.interrupts.SAME_INTERRUPT_S] later raises
``KeyboardInterrupt`` (the CLI turns it into a one-line exit too). ``vcjax launch``
forwards its interrupt to the processes it started and waits for them to write their results;
the processes of a tuning agree on the step to stop at
([`stop_requested_everywhere`][vcjax.runtime.interrupts.stop_requested_everywhere]).
After an interrupted guard, the interrupt's duplicate (a terminal's Ctrl-C reaches every
process of the group, and ``vcjax launch`` forwards it as well) is swallowed until
[`SAME_INTERRUPT_S`][vcjax.runtime.interrupts.SAME_INTERRUPT_S] after it, so it cannot break the
process's shutdown.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

import numpy as np

__all__ = [
    "EXIT_INTERRUPTED",
    "SAME_INTERRUPT_S",
    "interrupt_guard",
    "request_stop",
    "stop_requested",
    "stop_requested_everywhere",
    "stop_signal",
]

#: Exit code of a run stopped by SIGINT / SIGTERM (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130

_stop = threading.Event()
_stop_signal: list[int] = []
_stop_time: list[float] = [0.0]
#: Signals closer together than this [s] count as one interrupt.
SAME_INTERRUPT_S = 1.0


def stop_requested() -> bool:
    """Whether SIGINT / SIGTERM arrived inside ``interrupt_guard`` (polled by the loops)."""
    return _stop.is_set()


def stop_requested_everywhere() -> bool:
    """``stop_requested`` agreed by every process of a multi-process run (one small
    all-gather; call it at the same point in every process, e.g. after each tuning step, so
    that they all stop at the same step and none waits in a collective for one that stopped).
    One process: ``stop_requested``."""
    import jax

    if jax.process_count() == 1:
        return stop_requested()
    from jax.experimental import multihost_utils

    flags = multihost_utils.process_allgather(np.array(stop_requested()))
    return bool(np.any(flags))


def stop_signal() -> str | None:
    """Name of the signal that requested the stop (``"SIGINT"``, ``"SIGTERM"``), or None."""
    return signal.Signals(_stop_signal[0]).name if _stop_signal else None


def request_stop(signum: int = signal.SIGINT) -> None:
    """Ask the running loop to stop at its next safe point (what the signal handler does)."""
    if not _stop_signal:
        _stop_signal.append(int(signum))
    _stop.set()


@contextlib.contextmanager
def interrupt_guard():
    """Within the block, SIGINT / SIGTERM request a stop (``stop_requested``) instead of
    killing the process; a second signal raises ``KeyboardInterrupt``. On exit the
    handlers are restored and the flag cleared (a later run in the same process starts afresh;
    [`stop_signal`][vcjax.runtime.interrupts.stop_signal] still names the signal). Only in the main
    thread (elsewhere: no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        # a second signal stops at once -- unless it is the same interrupt arriving twice (a
        # terminal's Ctrl-C to the process group, and vcjax launch forwarding it): < 1 s apart
        if _stop.is_set() and time.monotonic() - _stop_time[0] > SAME_INTERRUPT_S:
            raise KeyboardInterrupt
        if not _stop.is_set():
            _stop_time[:] = [time.monotonic()]
        request_stop(signum)

    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _stop.clear()
    _stop_signal.clear()
    for s in old:
        signal.signal(s, handler)
    try:
        yield
    finally:
        interrupted = _stop.is_set()
        for s, h in old.items():
            # after an interrupt, its duplicate may still be on its way (vcjax launch forwards
            # the terminal's Ctrl-C that its processes got too): swallowed, so that it cannot
            # break the process's shutdown (a KeyboardInterrupt in JAX's exit handler leaves
            # the other processes of a distributed run waiting at its shutdown barrier)
            signal.signal(s, _after_interrupt(h) if interrupted else h)
        _stop.clear()


def _after_interrupt(old):
    """The handler to restore after an interrupted ``interrupt_guard``: a signal within
    [`SAME_INTERRUPT_S`][vcjax.runtime.interrupts.SAME_INTERRUPT_S] of the interrupt is the same
    interrupt (ignored); a later one gets
    the old handler's behaviour (which is also restored)."""
    old = signal.SIG_DFL if old is None else old

    def handler(signum, frame):
        if time.monotonic() - _stop_time[0] <= SAME_INTERRUPT_S:
            return
        signal.signal(signum, old)
        if callable(old):
            old(signum, frame)
        elif old == signal.SIG_DFL:
            os.kill(os.getpid(), signum)

    return handler
