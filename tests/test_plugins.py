"""The command seam of the CLI (vcjax.plugins): commands of other packages come from the
``vcjax.commands`` entry points; without them (a source tree never installed) asking for one is
one line naming the fix; a broken one leaves the others working."""

import importlib.metadata

import pytest

from vcjax import cli, plugins
from vcjax.plugins import GROUP, Command


def _hello(args) -> int:
    print(f"hello {args.who}")
    return 3


HELLO = Command(
    name="hello",
    help="say hello",
    add_arguments=lambda p: p.add_argument("who"),
    run=_hello,
    distributed=True,
)


def test_a_plugin_command_is_parsed_run_and_launchable(monkeypatch, capsys):
    monkeypatch.setattr(cli, "plugin_commands", lambda: (HELLO,))
    assert cli.main(["hello", "you"]) == 3
    assert capsys.readouterr().out == "hello you\n"
    assert "hello" in cli.build_parser().format_help()
    assert cli._distributed() == ["sweep", "hello"]


def test_without_the_entry_points_a_missing_command_is_one_line(monkeypatch, capsys):
    monkeypatch.setattr(cli, "plugin_commands", lambda: ())
    assert cli.main(["tune", "x.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vcjax: tune: no such command")
    assert "pip install -e ." in err and GROUP in err
    assert cli.main([]) == 0  # the built-in commands are all there
    assert "\n    tune " not in capsys.readouterr().out  # not listed
    assert cli._distributed() == ["sweep"]


def test_entry_points_are_loaded_checked_and_a_broken_one_is_left_out(monkeypatch, capsys):
    eps = [
        importlib.metadata.EntryPoint("tune", "tuning.command:COMMAND", GROUP),
        importlib.metadata.EntryPoint("tune", "tuning.command:COMMAND", GROUP),  # seen twice
        importlib.metadata.EntryPoint("broken", "no_such_module_xyz:COMMAND", GROUP),
        importlib.metadata.EntryPoint("other", "tuning.command:COMMAND", GROUP),  # name differs
    ]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: eps)
    plugins.plugin_commands.cache_clear()
    try:
        found = plugins.plugin_commands()
    finally:
        plugins.plugin_commands.cache_clear()
    assert [c.name for c in found] == ["tune"]
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "broken" in err[0] and "other" in err[1]


@pytest.mark.parametrize("argv", [["tune", "--help"], ["--help"]])
def test_the_installed_tune_command_keeps_its_help(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "tune a loop's gains by gradient descent" in out or "--max-memory-gb G" in out


def test_the_tuners_loss_metric_comes_from_its_entry_point(monkeypatch):
    """``metric = "loss"`` (falsify, ``sweep --scenario``) is the tuner's, found through the
    ``vcjax.metrics`` entry point; without it, one line naming the fix."""
    from vcjax import commands

    m = commands._loss_metric({})
    assert type(m).__name__ == "TuningLossMetric" and type(m).__module__ == "tuning.robust"
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: [])
    with pytest.raises(ValueError, match=r"metric loss: .*pip install -e \."):
        commands._loss_metric({})
