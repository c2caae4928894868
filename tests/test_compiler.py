"""The CLI's choice of XLA CPU code generator (vcjax.compiler): added to XLA_FLAGS unless the
user already chose, or turned it off, or the jaxlib predates the flag."""

import vcjax.compiler as comp
from vcjax.compiler import ENV, FLAG, prefer_fast_compile


def test_flag_is_added_once_and_yields_to_the_user(monkeypatch):
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 10))
    env = {}
    assert prefer_fast_compile(env) and env["XLA_FLAGS"] == FLAG
    assert prefer_fast_compile(env) and env["XLA_FLAGS"] == FLAG  # not twice
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert prefer_fast_compile(env)
    assert env["XLA_FLAGS"].split() == ["--xla_force_host_platform_device_count=2", FLAG]
    mine = "--xla_cpu_use_fusion_emitters=true"
    env = {"XLA_FLAGS": mine}
    assert not prefer_fast_compile(env) and env["XLA_FLAGS"] == mine  # the user's choice
    for off in ("0", "off", "False", " no "):
        env = {ENV: off}
        assert not prefer_fast_compile(env) and "XLA_FLAGS" not in env


def test_an_older_jaxlib_gets_no_flag(monkeypatch):
    """jaxlib 0.5 aborts on an XLA flag it does not know: nothing is added there."""
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 5))
    env = {}
    assert not prefer_fast_compile(env) and env == {}
