"""The command seam of ``vcjax``'s command line: commands that live in other packages (the
gain tuner's ``vcjax tune``, [`tuning.command`][tuning.command]) are found through Python entry
points, so that ``vcjax`` never imports them by name.

A package adds a command by declaring, in its ``pyproject.toml``::

    [project.entry-points."vcjax.commands"]
    tune = "tuning.command:COMMAND"

where ``COMMAND`` is a [`Command`][vcjax.plugins.Command]: its name (the entry point's), the
one-line help, a function adding its arguments to its ``argparse`` parser and the function
running it (exit status). Loading the entry point must be cheap (it happens for every
``vcjax`` invocation, ``--help`` included): import the command's work inside ``run``.
The entry points are read from the installed package metadata; a source tree that was never
installed has none (``pip install -e .`` writes them), and ``vcjax`` says so in one line when
such a command is asked for ([`missing_command`][vcjax.plugins.missing_command]).

Search metrics come the same way, from the ``vcjax.metrics`` group (``loss``: the tuner's
loss, ``tuning.robust``, for ``metric = "loss"``; read by ``vcjax.commands``).

What a command's body shares with the built-in ones (``vcjax.commands``) is re-exported here,
under public names: the kit of a plugin command.
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Callable
from dataclasses import dataclass

from vcjax import commands as _commands
from vcjax.commands import CLIError, fail, interruptible

__all__ = [
    "GROUP",
    "Command",
    "plugin_commands",
    "missing_command",
    "add_cpu_devices",
    "add_overwrite",
    "add_size_limits",
    "CLIError",
    "fail",
    "interruptible",
    "check_gains_file",
    "early_end",
    "enable_x64",
    "interrupted",
    "prepare",
    "record",
    "size_check",
    "use_cores",
]

# the kit: what the built-in commands' bodies use, under public names (see vcjax.commands)
check_gains_file = _commands._check_gains_file  # a gains file a config names, checked
early_end = _commands._early_end  # around the work after prepare: records an early end
enable_x64 = _commands._enable_x64  # the precision, before anything builds constants
interrupted = _commands._interrupted  # the one line of an interrupted run; exit code 130
prepare = _commands._prepare  # --out checked, cleared (--overwrite) and locked
record = _commands._record  # run.json written, the output folder released
size_check = _commands._size_check  # work that cannot fit refused before compiling
use_cores = _commands._use_cores  # --cpu-devices applied before JAX starts

#: the entry-point group of ``vcjax``'s commands
GROUP = "vcjax.commands"


@dataclass(frozen=True)
class Command:
    """One subcommand of ``vcjax`` from another package (the object an entry point of
    [`GROUP`][vcjax.plugins.GROUP] names).

    Attributes:
        name: the subcommand (``vcjax NAME``); equal to the entry point's name.
        help: its one line in ``vcjax --help``.
        add_arguments: adds its arguments to its parser (``argparse.ArgumentParser``).
        run: runs it on the parsed arguments; returns the exit status.
        distributed: whether ``vcjax launch`` may run it across processes.
        description: the text of ``vcjax NAME --help`` (default: none, as a built-in command).
    """

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    distributed: bool = False
    description: str | None = None


@functools.cache
def plugin_commands() -> tuple[Command, ...]:
    """The installed commands of [`GROUP`][vcjax.plugins.GROUP], by name; one that cannot be
    loaded is left out with a one-line warning (``vcjax`` keeps its other commands). Read once
    per process."""
    from importlib.metadata import entry_points

    found: dict[str, Command] = {}
    for ep in entry_points(group=GROUP):
        if ep.name in found:  # the same package seen twice on the path
            continue
        try:
            cmd = ep.load()
        except Exception as err:  # a broken plugin must not break every other command
            print(f"vcjax: command {ep.name} ({ep.value}) cannot be loaded: {err}", file=sys.stderr)
            continue
        if not isinstance(cmd, Command) or cmd.name != ep.name:
            print(
                f"vcjax: {ep.value} is not a vcjax.plugins.Command named {ep.name}", file=sys.stderr
            )
            continue
        found[ep.name] = cmd
    return tuple(found[k] for k in sorted(found))


def missing_command(name: str) -> str:
    """The one line when ``vcjax NAME`` names no command and no plugin command is installed:
    the metadata that lists them is missing (a source tree run without installing it)."""
    return (
        f"{name}: no such command, and no commands of other packages are installed (no "
        f"'{GROUP}' entry points: the package metadata is missing); from a source tree, "
        "run `pip install -e .`"
    )


def add_size_limits(p: argparse.ArgumentParser) -> None:
    """``--max-steps`` and ``--max-memory-gb``
    ([`vcjax.runtime.sizing`][vcjax.runtime.sizing])."""
    p.add_argument(
        "--max-steps",
        type=int,
        metavar="N",
        help="allow up to N steps per rollout (default 10,000,000)",
    )
    p.add_argument(
        "--max-memory-gb",
        type=float,
        metavar="G",
        help="allow an estimated peak memory up to G GB (default: 80%% of the physical memory)",
    )


def add_cpu_devices(p: argparse.ArgumentParser) -> None:
    """``--cpu-devices N``."""
    p.add_argument(
        "--cpu-devices",
        metavar="N",
        default=None,
        help="split the host CPU into N JAX devices and shard the scenarios over them "
        "(default: $VCJAX_CPU_DEVICES, else one per core; 1: no sharding)",
    )


def add_overwrite(p: argparse.ArgumentParser) -> None:
    """``--overwrite``."""
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier vcjax run: its files are removed first (files vcjax "
        "did not write are kept)",
    )
