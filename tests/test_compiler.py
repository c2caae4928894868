"""The CLI's choice of XLA CPU code generator (vcjax.runtime.compiler): added to XLA_FLAGS unless the
user already chose, or turned it off, or the jaxlib predates the flag."""

import functools

import pytest

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


def test_compile_options_follow_the_same_exceptions_as_the_flag(monkeypatch):
    """vcjax's own programs ask for the generator per program, on CPU, unless XLA_FLAGS already
    chooses it (either way), VCJAX_FAST_COMPILE is off, or the jaxlib is outside the checked range."""
    from vcjax.runtime.compiler import OPTION, compile_options

    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 10))
    assert compile_options({}) == {OPTION: False}  # the tests' backend is the CPU
    assert compile_options({"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}) == {
        OPTION: False
    }
    assert compile_options({"XLA_FLAGS": FLAG}) == {}  # the process-wide flag already applies
    assert compile_options({"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true"}) == {}  # yours
    for off in ("0", "off", "False", " no "):
        assert compile_options({ENV: off}) == {}
    for version in ((0, 5), (0, 11)):
        monkeypatch.setattr(comp, "_jaxlib_version", lambda v=version: v)
        assert compile_options({}) == {}
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 10))
    monkeypatch.setattr("jax.default_backend", lambda: "gpu")
    assert compile_options({}) == {}  # another backend: XLA's own choice


def _cumsum(x):
    import jax.numpy as jnp

    return jnp.cumsum(jnp.sin(x) * 2.0 + x[::-1]) @ jnp.cos(x)


def test_vcjax_jit_compiles_with_the_option_and_is_jax_jit_otherwise(monkeypatch):
    """The option reaches XLA: vcjax.jit's executable is the one jax.jit builds with the option
    given by hand (XLA's two CPU generators build different executables for a cumulative sum); with
    VCJAX_FAST_COMPILE off it is plain jax.jit's."""
    import jax
    import jax.numpy as jnp
    import pytest

    import vcjax
    from vcjax.runtime.compiler import OPTION

    if not comp._FIRST <= comp._jaxlib_version() <= comp.CHECKED:
        pytest.skip("a jaxlib without the option (vcjax.jit is jax.jit there)")
    x = jnp.arange(8.0)

    def text(**opts):
        return jax.jit(_cumsum, compiler_options=opts).lower(x).compile().as_text()

    fast, default = text(**{OPTION: False}), text(**{OPTION: True})
    if fast == default:
        pytest.skip("this XLA builds the same executable with either generator")
    monkeypatch.delenv("XLA_FLAGS", raising=False)  # the conftest's process-wide flag
    monkeypatch.delenv(ENV, raising=False)
    made, real = [], jax.jit
    monkeypatch.setattr(jax, "jit", lambda f, **kw: made.append(kw) or real(f, **kw))
    jitted = vcjax.jit(_cumsum)
    assert jitted.lower(x).compile().as_text() == fast
    assert float(jitted(x)) == pytest.approx(float(_cumsum(x)), rel=1e-12)
    assert made == [{"compiler_options": {OPTION: False}}]
    monkeypatch.setenv(ENV, "off")
    assert float(vcjax.jit(_cumsum)(x)) == pytest.approx(float(_cumsum(x)), rel=1e-12)
    assert made[1:] == [{}]  # plain jax.jit


def test_vcjax_jit_inside_another_jit_becomes_part_of_it(monkeypatch):
    """JAX refuses compile options on a jit traced inside another one: a vcjax.jit function
    (vcjax's own programs, e.g. the sweep's scenario sampler) called in a user's jax.jit is
    traced into that program instead of failing (it did, wherever XLA_FLAGS left the option
    on: a Python session; the option here is one every jaxlib takes)."""
    import jax
    import jax.numpy as jnp
    import pytest

    import vcjax

    monkeypatch.setattr(comp, "compile_options", lambda: {"xla_backend_optimization_level": 3})
    inner = vcjax.jit(_cumsum)
    x = jnp.arange(8.0)
    outer = jax.jit(lambda x: inner(x) + 1.0)
    assert float(outer(x)) == float(_cumsum(x)) + 1.0
    assert float(inner(x)) == float(_cumsum(x))  # and at the top level, with its option
    assert float(jax.jit(jax.grad(lambda x: inner(x)))(x)[0]) == float(jax.grad(_cumsum)(x)[0])
    with pytest.raises(TypeError):  # any other error still reaches the caller
        jax.jit(lambda x: inner(x, 1))(x)


def test_vcjax_jit_takes_jax_jit_arguments_and_decorates():
    import jax.numpy as jnp

    import vcjax

    @vcjax.jit
    def double(x):
        return 2.0 * x

    @functools.partial(vcjax.jit, static_argnames=("n",))
    def power(x, n):
        return x**n

    assert double.__name__ == "double" and float(double(jnp.asarray(1.5))) == 3.0
    assert float(power(jnp.asarray(2.0), n=3)) == 8.0
    assert float(power(jnp.asarray(2.0), n=2)) == 4.0
    assert power._cache_size() == 2  # one program per static value, as jax.jit
    assert vcjax.jit(static_argnums=(1,))(lambda x, n: x * n)(jnp.asarray(2.0), 3) == 6.0


def test_light_programs_ask_for_level_one_where_vcjax_chooses(monkeypatch):
    """``light_options``: LLVM's level 1 on the CPU, unless XLA_FLAGS sets the level (yours
    wins), VCJAX_FAST_COMPILE is off or the jaxlib is newer than the checked one; independent of
    the kernel generator's own exceptions (a light program asks for both where both apply)."""
    from vcjax.runtime.compiler import LIGHT, light_options

    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 10))
    assert light_options({}) == LIGHT
    assert light_options({"XLA_FLAGS": FLAG}) == LIGHT  # the generator chosen: not the level
    assert light_options({"XLA_FLAGS": "--xla_backend_optimization_level=0"}) == {}  # yours
    assert light_options({ENV: "off"}) == {}
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 5))  # before the generator's flag
    assert light_options({}) == LIGHT and comp.compile_options({}) == {}
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 11))  # unchecked: XLA's defaults
    assert light_options({}) == {}
    monkeypatch.setattr(comp, "_jaxlib_version", lambda: (0, 10))
    monkeypatch.setattr("jax.default_backend", lambda: "gpu")
    assert light_options({}) == {}


def test_a_light_program_compiles_with_both_options(monkeypatch):
    """``vcjax.jit(..., light=True)`` passes ``compile_options()`` and ``light_options()`` to its
    program (here both replaced, so that the test reads what the jitted function was given)."""
    import jax.numpy as jnp

    monkeypatch.setattr(comp, "compile_options", lambda: {"a": 1})
    monkeypatch.setattr(comp, "light_options", lambda: {"b": 2})
    seen = {}
    monkeypatch.setattr(
        "jax.jit", lambda fun, **kw: seen.update(kw.get("compiler_options", {})) or fun
    )
    assert comp.jit(jnp.sin, light=True)(0.0) == 0.0
    assert seen == {"a": 1, "b": 2}


def _draws(config, options):
    """Every leaf of 96 scenarios of the example sweep ``config``, drawn by its sampler compiled
    with ``options`` on top of vcjax's own (explicit options override the suite's level 0)."""
    from pathlib import Path

    import jax
    import jax.numpy as jnp
    import numpy as np

    from vcjax.sweep import load_config
    from vcjax.sweep import spec as S

    spec, _ = load_config(Path(__file__).parent.parent / "examples" / "sweeps" / config)
    loop = spec.loop(spec.variants[0])
    fn = jax.jit(S._sample._fun, static_argnames=("loop", "spec", "dtype"))
    idx = jnp.arange(96, dtype=jnp.int32)
    args = (loop, spec.scenario, "float64", jnp.asarray(spec.seed, jnp.uint32), idx)
    compiled = fn.lower(*args).compile({**comp.compile_options(), **options})
    out = compiled(args[3], idx)
    leaves = jax.tree_util.tree_leaves(out)
    return [
        np.asarray(jax.random.key_data(x) if jnp.issubdtype(x.dtype, jax.dtypes.prng_key) else x)
        for x in leaves
    ]


@pytest.mark.parametrize("config", ["large.toml", "remus100_waves.toml"])
def test_the_light_sampler_draws_the_same_bits_as_xla_default_level(config):
    """The sweep's scenario sampler is a light program (LLVM level 1): the same scenarios, bit
    for bit, as at XLA's default level 3, for draws of every kind (a Gauss-Markov current,
    initial offsets, model errors, sensor noise; a sea and REMUS 100's initial keys)."""
    from vcjax.runtime.compiler import LIGHT

    default = _draws(config, {"xla_backend_optimization_level": 3})
    light = _draws(config, LIGHT)
    assert len(default) == len(light) > 10
    for a, b in zip(default, light, strict=True):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
