"""The CLI's persistent compilation cache (vcjax.runtime.cache): folder choice, and a second identical
run that compiles nothing (every program read back from the cache)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vcjax.runtime.cache import default_cache_dir

ROOT = Path(__file__).parents[1]


def test_cache_folder_from_the_environment(tmp_path):
    home = Path.home()
    assert default_cache_dir({}) == home / ".cache" / "vcjax" / "jax"
    assert default_cache_dir({"XDG_CACHE_HOME": str(tmp_path)}) == tmp_path / "vcjax" / "jax"
    env = {"XDG_CACHE_HOME": "/elsewhere", "VCJAX_CACHE_DIR": str(tmp_path / "c")}
    assert default_cache_dir(env) == tmp_path / "c"
    for off in ("off", "OFF", " none ", "0", "false"):
        assert default_cache_dir({"VCJAX_CACHE_DIR": off}) is None
    assert default_cache_dir({"VCJAX_CACHE_DIR": ""}) == home / ".cache" / "vcjax" / "jax"


TOML = """
[sweep]
num_scenarios = 2
seed = 3
variants = ["vcm"]
chunk_size = 2

[simulation]
horizon = 1.0
dt = 0.1

[output]
figures = false
"""

# the CLI in a process that counts JAX's persistent-cache events (hits, misses)
RUN = """
import collections, json, sys
import jax.monitoring
counts = collections.Counter()
jax.monitoring.register_event_listener(lambda event, **kw: counts.update([event]))
from vcjax.cli import main
rc = main(sys.argv[1:])
print("EVENTS " + json.dumps(counts))
sys.exit(rc)
"""


def _run(cfg, out, cache):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update(JAX_PLATFORMS="cpu", VCJAX_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    r = subprocess.run(
        [sys.executable, "-c", RUN, "sweep", str(cfg), "--out", str(out), "--no-x64"],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    line = [s for s in r.stdout.splitlines() if s.startswith("EVENTS ")][-1]
    ev = json.loads(line[len("EVENTS ") :])
    return ev.get("/jax/compilation_cache/cache_hits", 0), ev.get(
        "/jax/compilation_cache/cache_misses", 0
    )


def _entries(cache: Path) -> dict:
    return {p.name: p.stat().st_size for p in cache.rglob("*") if p.is_file()}


@pytest.mark.slow  # two CLI processes (~15-30 s on 2 cores)
@pytest.mark.skipif(
    __import__("vcjax.runtime.cache").runtime.cache.unsafe_version() is not None,
    reason="this jaxlib's persistent cache stays off (vcjax.runtime.cache.SAFE_FROM)",
)
def test_second_identical_run_compiles_nothing(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TOML)
    cache = tmp_path / "cache"
    hits1, misses1 = _run(cfg, tmp_path / "o1", cache)
    assert misses1 > 0  # a cold cache: every program compiled and written
    first = _entries(cache)
    assert first, "nothing was written to the cache"
    hits2, misses2 = _run(cfg, tmp_path / "o2", cache)
    assert misses2 == 0 and hits2 >= misses1, (hits2, misses2, misses1)
    assert _entries(cache).keys() == first.keys()  # nothing new written
    info = json.loads((tmp_path / "o2" / "run.json").read_text())
    assert info["compilation_cache"] == str(cache)


def test_off_disables_and_run_json_says_so(tmp_path):
    import jax

    from vcjax.runtime import cache, runinfo

    before = jax.config.jax_enable_compilation_cache
    try:
        assert cache.enable_compilation_cache({"VCJAX_CACHE_DIR": "off"}) is None
        assert not jax.config.jax_enable_compilation_cache
        assert runinfo.run_info("test")["compilation_cache"] is None
        if cache.unsafe_version() is not None:  # this jaxlib: the cache stays off (tested below)
            return
        d = cache.enable_compilation_cache({"VCJAX_CACHE_DIR": str(tmp_path / "c")})
        assert d == str(tmp_path / "c") and (tmp_path / "c").is_dir()
        assert jax.config.jax_compilation_cache_dir == d
        assert runinfo.run_info("test")["compilation_cache"] == d
    finally:
        cache.enable_compilation_cache({"VCJAX_CACHE_DIR": "off"})
        jax.config.update("jax_compilation_cache_dir", None)
        jax.config.update("jax_enable_compilation_cache", before)


def test_the_cache_stays_off_on_jax_versions_that_read_programs_back_wrongly(tmp_path):
    """jaxlib 0.5.1 reads a ``jax.random.gamma`` program back from its persistent cache as one
    that returns a constant (found by the minimum-versions test run: the sea's directional
    spreading collapsed on the second read); below SAFE_FROM the cache stays off, with the
    reason."""
    from vcjax.runtime import cache

    assert cache.unsafe_version("0.5.1") and "0.6.2" in cache.unsafe_version("0.5.3")
    assert cache.unsafe_version("0.6.2") is None and cache.unsafe_version("0.10.2") is None
    assert cache.unsafe_version("0.6.10") is None and cache.unsafe_version("0.7.0.dev2025") is None
    if cache.unsafe_version() is not None:  # this environment's jaxlib: left off, and why
        assert cache.enable_compilation_cache({cache.ENV: str(tmp_path / "c")}) is None
        assert cache.cache_dir() is None and "gamma" in cache.cache_off_reason()


GAMMA = """
import sys, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from vcjax.runtime.cache import enable_compilation_cache
print("cache", enable_compilation_cache())
f = jax.jit(lambda k, a: jax.random.gamma(k, a, (4,), dtype=jnp.float64))
print(np.asarray(f(jax.random.PRNGKey(3), 2.0)).tolist())
"""


@pytest.mark.slow  # two fresh processes
def test_a_gamma_program_read_back_from_the_cache_draws_the_same_numbers(tmp_path):
    env = dict(os.environ, JAX_PLATFORMS="cpu", VCJAX_CACHE_DIR=str(tmp_path / "c"))
    env["PYTHONPATH"] = str(ROOT)
    outs = [
        subprocess.run([sys.executable, "-c", GAMMA], env=env, capture_output=True, text=True)
        for _ in range(2)
    ]
    assert all(o.returncode == 0 for o in outs), outs[-1].stderr[-2000:]
    first, second = (o.stdout.splitlines() for o in outs)
    assert first[1] == second[1]  # cached (or, where the cache stays off, compiled again)
    assert len(set(json.loads(first[1]))) == 4  # four different draws, not a constant
