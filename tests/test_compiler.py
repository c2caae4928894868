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


def _run(code: str, **env):
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    base = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", ENV)}
    base["PYTHONPATH"] = str(root)
    base.update(env)
    return subprocess.run(
        [sys.executable, "-c", code], env=base, cwd=root, capture_output=True, text=True
    )


def test_fast_compile_sets_the_flag_and_a_program_compiles():
    """vcjax.fast_compile() in a fresh process: XLA_FLAGS carries the flag, XLA accepts it (an
    unknown flag would abort the process) and a jitted program compiles and runs."""
    code = (
        "import os, vcjax\n"
        "on = vcjax.fast_compile()\n"
        "import jax, jax.numpy as jnp\n"
        "y = jax.jit(lambda x: jnp.sin(x) * 2.0).lower(jnp.arange(3.0)).compile()(jnp.arange(3.0))\n"
        "print(on, repr(os.environ.get('XLA_FLAGS', '')), float(y[1]))\n"
    )
    res = _run(code)
    assert res.returncode == 0, res.stderr
    on, flags, value = res.stdout.split()
    import math

    assert abs(float(value) - 2 * math.sin(1.0)) < 1e-6
    expected = FLAG in flags
    assert on == str(expected)
    if comp.jaxlib_version(2) >= (0, 6) and comp.jaxlib_version(2) <= comp.CHECKED:
        assert on == "True" and FLAG in flags


def test_fast_compile_after_the_backend_started_raises():
    """Too late to take effect: a clear error, and XLA_FLAGS is left as it was."""
    code = (
        "import os, jax, jax.numpy as jnp, vcjax\n"
        "jnp.zeros(2).block_until_ready()\n"
        "try:\n"
        "    vcjax.fast_compile()\n"
        "except vcjax.runtime.compiler.BackendStartedError as e:\n"
        "    print('raised', 'before the first JAX computation' in str(e))\n"
        "print(repr(os.environ.get('XLA_FLAGS', '')))\n"
    )
    res = _run(code)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split("\n")[:2] == ["raised True", "''"]


def test_fast_compile_respects_the_opt_out():
    res = _run(
        "import os, vcjax\nprint(vcjax.fast_compile(), os.environ.get('XLA_FLAGS'))\n",
        **{ENV: "off"},
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["False", "None"]
