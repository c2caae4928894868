"""The CLI's persistent compilation cache (vcjax.runtime.cache): folder choice, and a second identical
run that compiles nothing (every program read back from the cache)."""

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest

from vcjax.runtime.cache import default_cache_dir

ROOT = Path(__file__).parents[1]


def _pythonpath() -> str:
    """This checkout first, then the caller's own ``PYTHONPATH``."""
    return os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH", "")]))


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
    env.update(JAX_PLATFORMS="cpu", VCJAX_CACHE_DIR=str(cache), PYTHONPATH=_pythonpath())
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
    # the batch program was not traced again: loaded from the program store, and its
    # executable (compiled from the loaded form in both runs) read back from XLA's cache
    progs = info["programs"]
    if progs.get("store_off"):  # no flatbuffers: the store stays off, the run as before
        assert progs["store"] is None and not any(b["reused"] for b in progs["built"])
    else:
        assert progs["store"] == str(cache / "programs")
        assert [b["reused"] for b in progs["built"]] == [True]
        first_run = json.loads((tmp_path / "o1" / "run.json").read_text())["programs"]
        assert [b["reused"] for b in first_run["built"]] == [False]


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


# ----------------------------------------------------------------------------- program store


def _loop_static(horizon=1.0, controller="vcm", **choice):
    from vcjax.sweep.spec import SweepSpec

    spec = SweepSpec(num_scenarios=2, variants=(controller,), horizon=horizon, dt=0.1, **choice)
    return spec.loop(controller), spec.mc_config()


def test_the_program_key_changes_with_everything_that_changes_the_program(monkeypatch):
    """Exact invalidation: the static inputs (loop, rollout settings), the arguments' shapes and
    dtypes, the code (vcjax version, source hash), XLA_FLAGS and JAX's settings each change the
    key; new values of the same shapes do not."""
    import jax.numpy as jnp

    from vcjax.runtime import programs

    static = _loop_static()
    args = (jnp.ones(3), {"a": jnp.zeros((2, 2))})
    key = programs.program_key("p", static, args)
    assert programs.program_key("p", _loop_static(), (jnp.ones(3) * 7.0, {"a": jnp.ones((2, 2))}))\
        == key  # fmt: skip
    changed = {
        "name": programs.program_key("q", static, args),
        "horizon": programs.program_key("p", _loop_static(horizon=2.0), args),
        "controller": programs.program_key("p", _loop_static(controller="ilos"), args),
        "shape": programs.program_key("p", static, (jnp.ones(4), {"a": jnp.zeros((2, 2))})),
        "dtype": programs.program_key("p", static, (jnp.ones(3, jnp.float32), args[1])),
        "weak type": programs.program_key("p", static, (jnp.full(3, 1.0), args[1])),
        "tree": programs.program_key("p", static, (jnp.ones(3), {"b": jnp.zeros((2, 2))})),
    }
    flags = os.environ.get("XLA_FLAGS", "")
    monkeypatch.setenv("XLA_FLAGS", f"{flags} --xla_cpu_use_fusion_emitters=true".strip())
    changed["xla_flags"] = programs.program_key("p", static, args)
    monkeypatch.undo()
    monkeypatch.setattr(programs, "source_hash", lambda: "edited")
    changed["source"] = programs.program_key("p", static, args)
    monkeypatch.undo()
    # the version is vcjax/__init__.py's text, part of the source hash above: a new version
    # is an edited source
    import jax

    before = jax.config.jax_default_matmul_precision
    try:
        jax.config.update("jax_default_matmul_precision", "highest")
        changed["jax config"] = programs.program_key("p", static, args)
    finally:
        jax.config.update("jax_default_matmul_precision", before)
    assert programs.program_key("p", static, args) == key  # all undone
    stale = [what for what, k in changed.items() if k == key]
    assert not stale, f"the key ignores: {stale}"
    assert len(set(changed.values())) == len(changed)


def test_the_program_key_is_the_same_in_a_new_process(monkeypatch):
    """What makes a second run find the program: the key does not depend on the process
    (no memory addresses: the loop's path function is described by module, name and code).
    The user source files a process has loaded are part of the key (tested below); this test
    session loads more of them than the subprocesses, so that part is left out of the
    comparison with it."""
    code = (
        "import jax; jax.config.update('jax_enable_x64', True)\n"
        "jax.config.update('jax_numpy_dtype_promotion', 'strict')\n"
        "import jax.numpy as jnp\n"
        "from tests.test_cache import _loop_static\n"
        "from vcjax.runtime import programs\n"
        "print(programs.program_key('p', _loop_static(), (jnp.ones(3),)))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update(JAX_PLATFORMS="cpu", PYTHONPATH=_pythonpath())
    keys = []
    for _ in range(2):
        r = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True,
                           text=True, timeout=300)  # fmt: skip
        assert r.returncode == 0, r.stderr[-2000:]
        keys.append(r.stdout.split()[-1])
    import jax.numpy as jnp

    from vcjax.runtime import programs

    assert keys[0] == keys[1] and len(keys[0]) == 64
    if os.environ.get("XLA_FLAGS") is None:  # this session has the same settings: the same key
        sub = code.replace("print(", "programs.user_sources = lambda: ()\nprint(")
        same = {k: v for k, v in env.items() if k != "JAX_PLATFORMS" or k in os.environ}
        r = subprocess.run([sys.executable, "-c", sub], env=same, cwd=ROOT, capture_output=True,
                           text=True, timeout=300)  # fmt: skip
        monkeypatch.setattr(programs, "user_sources", lambda: ())
        here = programs.program_key("p", _loop_static(), (jnp.ones(3),))
        assert here == r.stdout.split()[-1]


_OPAQUE = object()


def test_an_unstable_static_input_is_not_stored():
    from vcjax.runtime import programs

    with pytest.raises(programs.Unstable):
        programs.describe(object())
    with pytest.raises(programs.Unstable):
        programs.describe(lambda x, o=_OPAQUE: x)


@pytest.fixture
def store(tmp_path):
    from vcjax.runtime import programs

    pytest.importorskip("flatbuffers")  # jax.export's serialisation
    folder = programs.set_store(tmp_path / "programs")
    try:
        yield folder
    finally:
        programs.set_store(None)


def test_a_stored_program_is_reused_and_gives_the_same_numbers(store):
    """The first build exports and stores, the second loads (no tracing: the Python function
    is not called again); both give the numbers of the plain jitted function."""
    import jax
    import jax.numpy as jnp

    from vcjax.runtime import programs

    traced = []

    def f(x, p):
        traced.append(1)
        return {"y": jnp.sin(x) * p["k"] + jnp.cumsum(x)}

    x, p = jnp.linspace(0.0, 1.0, 5), {"k": jnp.asarray(3.0)}
    ref = jax.jit(f)(x, p)["y"]
    n0 = len(traced)
    call1, info1 = programs.build("f", f, ("f", 1), (x, p))
    assert not info1["reused"] and len(traced) == n0 + 1
    assert len(list(store.glob("*" + programs.SUFFIX))) == 1
    call2, info2 = programs.build("f", f, ("f", 1), (x, p))
    assert info2["reused"] and len(traced) == n0 + 1  # not traced again
    assert info2["key"] == info1["key"]
    x2 = x + 1.0
    assert jnp.array_equal(call1(x, p)["y"], ref) and jnp.array_equal(call2(x, p)["y"], ref)
    assert jnp.array_equal(call2(x2, p)["y"], jax.jit(f)(x2, p)["y"])  # new values, same program
    # another static input: a new program, not the stored one
    _, info3 = programs.build("f", f, ("f", 2), (x, p))
    assert not info3["reused"] and info3["key"] != info1["key"]
    assert [r["reused"] for r in programs.report()] == [False, True, False]


class _Pair(NamedTuple):
    """An output pytree jax.export cannot serialise by itself (a NamedTuple)."""

    a: object
    b: object


def test_any_output_pytree_is_stored_and_an_unpicklable_one_is_built_unstored(store):
    import jax.numpy as jnp

    from vcjax.runtime import programs

    f = lambda x: _Pair(x * 2.0, {"s": jnp.sum(x)})  # noqa: E731
    x = jnp.arange(3.0)
    outs = [programs.build("pair", f, "pair", (x,)) for _ in range(2)]
    assert [info["reused"] for _, info in outs] == [False, True]
    for call, _ in outs:
        got = call(x + 1.0)
        assert isinstance(got, _Pair) and jnp.array_equal(got.a, (x + 1.0) * 2.0)
        assert float(got.b["s"]) == 6.0

    class Local(NamedTuple):  # pickle cannot name it: compiled as before, nothing stored
        y: object

    call, info = programs.build("local", lambda x: Local(x + 1.0), "local", (x,))
    assert info["key"] is None and not info["reused"]
    assert jnp.array_equal(call(x).y, x + 1.0)
    assert len(list(store.glob("*" + programs.SUFFIX))) == 1


def test_a_program_built_ahead_falls_back_for_other_arguments(store):
    import jax
    import jax.numpy as jnp

    from vcjax.runtime import programs

    f = lambda x: jnp.cumsum(x)  # noqa: E731
    x = jnp.ones(3)
    ((call, _),) = programs.build_all([("c", f, "c", (x,))])
    run = programs.for_arguments_like(call, (x,), jax.jit(f))
    assert jnp.array_equal(run(x), jnp.arange(1.0, 4.0))
    assert jnp.array_equal(run(jnp.ones(5)), jnp.arange(1.0, 6.0))  # another shape: the fallback


def test_a_program_builds_from_shapes_alone(store):
    """``jax.ShapeDtypeStruct`` arguments (a sweep builds its programs while drawing the batch):
    with a sharding they stand for arrays committed there (the key of the arrays: a run built
    from them finds it), without one for arrays not placed yet; the program runs on the
    arrays."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from vcjax.runtime import programs

    f = lambda x, k: {"y": jnp.sin(x) * k}  # noqa: E731
    sh = NamedSharding(Mesh(np.asarray(jax.devices()[:1]), ("b",)), PartitionSpec("b"))
    x, k = jax.device_put(jnp.linspace(0.0, 1.0, 4), sh), jnp.asarray(2.0)
    shape = jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sh)
    assert programs.program_key("s", "s", (shape, k)) == programs.program_key("s", "s", (x, k))
    call, info = programs.build("s", f, "s", (shape, k))
    assert not info["reused"] and jnp.array_equal(call(x, k)["y"], jax.jit(f)(x, k)["y"])
    free = jax.ShapeDtypeStruct(x.shape, x.dtype)
    call, info = programs.build("u", f, "u", (free, k))
    y = jnp.linspace(0.0, 1.0, 4)
    assert info["key"] is not None and jnp.array_equal(call(y, k)["y"], jax.jit(f)(y, k)["y"])


def test_a_damaged_file_is_rebuilt(store):
    import jax.numpy as jnp

    from vcjax.runtime import programs

    f = lambda x: x * 2.0  # noqa: E731
    _, info = programs.build("g", f, "g", (jnp.ones(2),))
    (path,) = store.glob("*" + programs.SUFFIX)
    path.write_bytes(b"not a program")
    call, info2 = programs.build("g", f, "g", (jnp.ones(2),))
    assert not info2["reused"] and jnp.array_equal(call(jnp.ones(2)), jnp.full(2, 2.0))


def test_the_store_is_bounded_least_recently_used_first(tmp_path):
    from vcjax.runtime import programs

    for i, name in enumerate(("old", "mid", "new")):
        path = tmp_path / f"{name}{programs.SUFFIX}"
        path.write_bytes(b"x" * 100)
        os.utime(path, (1000.0 + i, 1000.0 + i))
    (tmp_path / "other.txt").write_bytes(b"x" * 1000)  # not a program: never removed
    removed = programs.evict(tmp_path, 250)
    assert [p.name for p in removed] == [f"old{programs.SUFFIX}"]
    assert (tmp_path / "other.txt").exists()
    assert programs.evict(tmp_path, 250) == []
    removed = programs.evict(tmp_path, 0)
    assert sorted(p.name for p in removed) == sorted(
        f"{n}{programs.SUFFIX}" for n in ("mid", "new")
    )


def test_off_turns_the_store_off(tmp_path):
    import jax

    from vcjax.runtime import cache, programs, runinfo

    before = jax.config.jax_enable_compilation_cache
    try:
        cache.enable_compilation_cache({"VCJAX_CACHE_DIR": "off"})
        assert programs.store_dir() is None
        assert runinfo.run_info("test")["programs"]["store"] is None
        if cache.unsafe_version() is None:
            cache.enable_compilation_cache({"VCJAX_CACHE_DIR": str(tmp_path / "c")})
            if programs.off_reason() is None:
                assert programs.store_dir() == tmp_path / "c" / "programs"
            else:
                assert programs.store_dir() is None and "flatbuffers" in programs.off_reason()
    finally:
        cache.enable_compilation_cache({"VCJAX_CACHE_DIR": "off"})
        jax.config.update("jax_compilation_cache_dir", None)
        jax.config.update("jax_enable_compilation_cache", before)


def test_the_tuners_value_and_grad_is_stored_and_reused(store):
    """``vcjax tune``'s L-BFGS step: the batch value-and-gradient comes from the store on a
    second identical run (not traced), with the same iterates as without a store."""
    import jax.numpy as jnp

    from tuning.optim import run_gradient_tuner
    from vcjax.runtime import programs

    def loss(theta, target, w):
        return jnp.sum(w * (theta - target) ** 2) + 0.1 * jnp.sum(jnp.sin(theta) ** 2)

    args = (jnp.asarray([1.0, -2.0, 0.5]), jnp.asarray([1.0, 3.0, 0.5]))
    kw = dict(optimizer="lbfgs", steps=5)
    runs = [
        run_gradient_tuner(loss, jnp.zeros(3), args, program_static=("quadratic", 1), **kw)
        for _ in range(2)
    ]
    assert [r["reused"] for r in programs.report()] == [False, True]
    programs.set_store(None)
    plain = run_gradient_tuner(loss, jnp.zeros(3), args, **kw)
    for res in runs:
        assert jnp.array_equal(res.theta, plain.theta)
        assert [h["loss"] for h in res.history] == [h["loss"] for h in plain.history]


def test_the_black_box_tuners_batch_loss_is_stored_and_reused(store):
    """The black-box tuners' batch loss (CMA-ES, TPE, random search) keyed like the gradient
    tuner's step: a second objective with the same description loads the program, values
    unchanged; without a description nothing is stored."""
    import jax.numpy as jnp
    import numpy as np

    from tuning.blackbox import batch_objective
    from vcjax.runtime import programs

    def loss(theta, target):
        return jnp.sum((theta - target) ** 2)

    args = (jnp.asarray([1.0, -2.0]),)
    X = np.array([[0.0, 0.0], [1.0, -2.0], [np.inf, 0.0]])
    vals = [batch_objective(loss, args, static=("quadratic", 2))(X) for _ in range(2)]
    assert [r["reused"] for r in programs.report()] == [False, True]
    np.testing.assert_array_equal(vals[0], [5.0, 0.0, np.inf])
    np.testing.assert_array_equal(vals[1], vals[0])
    batch_objective(loss, args)(X)
    assert len(programs.report()) == 2


def test_an_edit_to_a_users_module_changes_the_program_key(tmp_path):
    """A law, loop or component in a user's file (``[scenario] module``) is traced into the
    program: an edit anywhere in that file must never reuse the program stored before it (a
    stored sweep once kept running the old law after its file changed)."""
    import jax.numpy as jnp

    from vcjax.config.scenario import import_module_file
    from vcjax.runtime import programs

    f = tmp_path / "my_law.py"
    f.write_text("GAIN = 1.0\n\ndef helper(x):\n    return GAIN * x\n")
    import_module_file(f)
    args = (jnp.zeros(3),)
    before = programs.program_key("p", ("static",), args)
    assert str(f.resolve()) in dict(programs.user_sources())
    assert programs.program_key("p", ("static",), args) == before  # the same file: the same key
    f.write_text("GAIN = 3.0\n\ndef helper(x):\n    return GAIN * x\n")  # a module-level edit
    assert programs.program_key("p", ("static",), args) != before
