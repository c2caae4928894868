"""A second process that draws figures beside this one.

Drawing is Python under its interpreter lock: one core, whatever the machine has. A
[`FigureHelper`][vcjax.plots.helper.FigureHelper] starts a fresh Python process (``python -m
vcjax.plots.helper``: nothing of this process's JAX runtime is copied) that loads Matplotlib and
vcjax's figure modules while this process is still tracing and compiling, then draws the
figures it is given on a core of its own while this process draws the others. ``vcjax sweep``
draws two of its four figures there: a cold REMUS 100 sweep ends about 0.7 s sooner (the
performance page).

The helper receives plain data (NumPy arrays, strings, numbers, paths; pickled through its
standard input) and a figure function's name in a figure module it knows
(``vcjax.plots.sweep``); it writes its
figure file itself (atomically, like every figure) and answers with the file's path. Whatever
fails there (the process did not start, could not import vcjax, died, the figure raised, or
no answer came within [`result`][vcjax.plots.helper.FigureHelper.result]'s timeout) is drawn
here instead, so a figure never goes missing because of the helper:
[`submit`][vcjax.plots.helper.FigureHelper.submit] returns False, or
[`result`][vcjax.plots.helper.FigureHelper.result] None, and the caller draws it. The helper
ignores Ctrl-C (this process decides) and is stopped by
[`close`][vcjax.plots.helper.FigureHelper.close]; it also ends when this process does (its
input closes).

``VCJAX_FIGURE_HELPER=off`` turns it off; it is not started on a single core.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import threading

__all__ = ["ENV", "FigureHelper", "wanted"]

#: the environment variable that turns the helper off (``0``, ``off``, ``false``, ``no``)
ENV = "VCJAX_FIGURE_HELPER"
_OFF = ("0", "off", "false", "no")


def wanted(environ=None) -> bool:
    """Whether a helper may start: not turned off by ``VCJAX_FIGURE_HELPER``, and at least two
    cores for this process."""
    from vcjax.runtime.devices import usable_cores

    env = os.environ if environ is None else environ
    return env.get(ENV, "").strip().lower() not in _OFF and usable_cores() >= 2


def _figure_module(name: str):
    """The module of figure functions ``name`` (a fixed list: the helper imports nothing by a
    name it is given)."""
    if name == "vcjax.plots.sweep":
        from vcjax.plots import sweep

        return sweep
    raise ValueError(f"not a figure module of the helper: {name!r}")


def _serve(modules, inp, out) -> None:
    """The helper's loop: load ``modules`` (and Matplotlib through them), then make each list
    of ``(module, function, args)`` read from ``inp``, answering ``("ok", path)`` or
    ``("error", text)`` on ``out`` for each call; ends at None or at the end of ``inp``."""
    try:
        for name in modules:
            _figure_module(name)
        from vcjax.plots import pyplot

        pyplot()
    except Exception as err:  # noqa: BLE001 - said in answer to every call
        failed = f"{type(err).__name__}: {err}"
    else:
        failed = None

    def answer(reply) -> None:  # length-prefixed: the parent reads it without a buffer
        data = pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL)
        out.write(len(data).to_bytes(8, "little") + data)
        out.flush()

    while True:
        try:
            calls = pickle.load(inp)
        except (EOFError, OSError, pickle.UnpicklingError):
            return
        if calls is None:
            return
        for module, function, args in calls:
            if failed is not None:
                answer(("error", failed))
                continue
            try:
                path = getattr(_figure_module(module), function)(*args)
                answer(("ok", str(path)))
            except Exception as err:  # noqa: BLE001 - the parent draws it instead
                answer(("error", f"{type(err).__name__}: {err}"))


def main(modules) -> None:
    """The helper process (``python -m vcjax.plots.helper MODULE ...``): answers on the standard
    output it was started with, and sends everything printed to the standard error."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when to stop
    out = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # nothing else may write the answers
    _serve(modules, sys.stdin.buffer, out)


class FigureHelper:
    """A helper process for figures (module docstring), started at once: it loads
    ``modules`` (names of ``vcjax.plots`` modules) while this process goes on."""

    def __init__(self, modules=("vcjax.plots.sweep",)):
        self._lock = threading.Lock()
        self._pending = 0
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "vcjax.plots.helper", *modules],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            close_fds=True,
            bufsize=0,  # answers are read from the pipe itself (waited on, no read-ahead)
        )

    def submit(self, calls) -> bool:
        """Ask the helper to make ``calls``, a list of ``(module, function, args)`` (figure
        functions that write their file and return its path), one after another; one message,
        so that this process does not wait while the helper draws. False when it cannot be
        asked (draw them here)."""
        calls = list(calls)
        with self._lock:
            if self._proc.poll() is not None:  # ended (or closed): draw them here
                return False
            try:
                data = pickle.dumps(calls, protocol=pickle.HIGHEST_PROTOCOL)
                self._proc.stdin.write(data)
                self._proc.stdin.flush()
            except Exception:  # noqa: BLE001 - arguments that do not pickle, a closed pipe
                return False
            self._pending += len(calls)
            return True

    def result(self, timeout: float = 300.0):
        """The path of the next figure submitted, in order; None when the helper failed on it
        (draw it here), also when it has not answered within ``timeout`` seconds (a helper
        that hangs never holds the command up for longer; it is given nothing more)."""
        with self._lock:
            if self._pending == 0 or self._proc.stdout is None:
                return None
            self._pending -= 1
            try:
                size = int.from_bytes(self._read(8, timeout), "little")
                status, value = pickle.loads(self._read(size, timeout))
            except Exception:  # noqa: BLE001 - it died or is silent: the rest are drawn here
                self._pending = 0
                return None
        return value if status == "ok" else None

    def _read(self, n: int, timeout: float) -> bytes:
        """``n`` bytes of the helper's answers, waiting at most ``timeout`` seconds for each
        part (raises when it ended or stayed silent)."""
        fd = self._proc.stdout.fileno()
        chunks, left = [], n
        while left:
            if not self._answer_within(timeout):
                raise TimeoutError("the figure helper did not answer")
            chunk = os.read(fd, left)
            if not chunk:
                raise EOFError("the figure helper ended")
            chunks.append(chunk)
            left -= len(chunk)
        return b"".join(chunks)

    def _answer_within(self, timeout: float) -> bool:
        """Whether the pipe of answers can be read within ``timeout`` seconds (False: the
        helper is silent; at its end the pipe reads empty); where pipes cannot be waited on
        (Windows), a read is simply tried."""
        import select
        import time

        deadline = time.monotonic() + timeout
        while True:
            try:
                ready, _, _ = select.select([self._proc.stdout], [], [], 0.5)
            except (OSError, ValueError):  # no select on pipes here
                return True
            if ready or self._proc.poll() is not None:  # an ended helper's pipe reads empty
                return True
            if time.monotonic() > deadline:
                return False

    def close(self) -> None:
        """End the helper now (one still loading or drawing is stopped: nothing it owes is
        waited for)."""
        with self._lock:
            self._pending = 0
            if self._proc.poll() is None:
                self._proc.terminate()
            try:
                self._proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
            for pipe in (self._proc.stdin, self._proc.stdout):
                if pipe is not None:
                    try:
                        pipe.close()
                    except OSError:
                        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


if __name__ == "__main__":  # pragma: no cover - the helper process itself
    main(sys.argv[1:])
