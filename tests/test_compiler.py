"""The CLI's choice of XLA CPU code generator (vcjax.runtime.compiler): added to XLA_FLAGS unless the
user already chose, or turned it off, or the jaxlib predates the flag."""

import vcjax.runtime.compiler as comp
from vcjax.runtime.compiler import ENV, FLAG, prefer_fast_compile


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


def test_a_jaxlib_newer_than_the_checked_one_gets_no_flag(monkeypatch):
    """XLA may retire the flag, and an unknown flag aborts: an unchecked jaxlib gets XLA's own."""
    for version in ((0, 11), (1, 0)):
        monkeypatch.setattr(comp, "_jaxlib_version", lambda v=version: v)
        env = {}
        assert not prefer_fast_compile(env) and env == {}
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: comp.CHECKED)
    env = {}
    assert prefer_fast_compile(env) and env["XLA_FLAGS"] == FLAG


def test_jaxlib_version_reads_release_and_pre_release_spellings():
    from vcjax.runtime.compiler import jaxlib_version

    assert jaxlib_version(2, "0.10.2") == (0, 10)
    assert jaxlib_version(3, "0.6.2") == (0, 6, 2)
    assert jaxlib_version(3, "0.7.0rc1") == (0, 7, 0)
    assert jaxlib_version(3, "0.7.0.dev20250101") == (0, 7, 0)
    assert jaxlib_version(3, "0.6") == (0, 6, 0)
    assert jaxlib_version(3, "x.6.1") == (0, 6, 1)
