"""The README and the documentation stay true.

* every fenced ``python`` block of ``README.md`` and ``docs/**/*.md`` runs as written (the blocks
  of one page in order, sharing a namespace), and what its comments claim is checked here
  against something independent of the code that produced it;
* every fenced ``bash`` block is checked: each ``vcjax`` command line parses with the CLI's own
  parser, each ``python -m``/``python FILE`` command exists and accepts the flags used (its
  ``--help`` lists them), and every repository file a command names exists;
* every link and image of those pages points to a file in the repository or to a public
  ``http(s)`` address; nothing refers to anything outside the repository;
* the README is short and its two set-up commands are what ``.ci/run`` runs;
* the site builds with ``mkdocs build --strict`` (where the ``docs`` extra is installed, as in CI).
"""

from __future__ import annotations

import importlib.util
import re
import shlex
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", flags=re.S | re.M)


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def blocks(page: Path, lang: str) -> list[str]:
    return [code for kind, code in FENCE.findall(page.read_text()) if kind == lang]


def run_page(page: Path) -> dict:
    # a real module, so that dataclasses defined in a page can look their module up
    mod = types.ModuleType("docs_page_" + re.sub(r"\W", "_", _rel(page)))
    sys.modules[mod.__name__] = mod
    try:
        for code in blocks(page, "python"):
            exec(compile(code, _rel(page), "exec"), mod.__dict__)
    finally:
        del sys.modules[mod.__name__]
    return mod.__dict__


PY_PAGES = [p for p in PAGES if blocks(p, "python")]


# --------------------------------------------------------------------------- claims per page


def _claims_first_loop(ns):
    # "mean |e| over the last 20 % of 60 s: ~1e-4 m, True" -- recomputed from the stored
    # trajectory's true positions (distance to the line x = 10 m), not from the metrics code
    traj, sc, loop = ns["traj"], ns["sc"], ns["loop"]
    pos = np.asarray(loop.signals(traj, sc).pos)
    e = np.abs(pos[:, 0] - 10.0)
    k0 = int(0.8 * len(e))
    assert 1e-6 < np.mean(e[k0:]) < 1e-3
    np.testing.assert_allclose(float(ns["m"]["ss_abs_e"]), np.mean(e[k0:]), rtol=1e-6)
    assert bool(traj.healthy)


def _claims_engine(ns):
    # "Φ decays as exp(−P_Φ t)" -- against the analytic solution of (14), and "rank 2"
    traj = ns["traj"]
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    P_Phi = np.asarray(ns["gains"].P_Phi)
    expected = Phi[0] * np.exp(-P_Phi * t[:, None])
    np.testing.assert_allclose(Phi, expected, atol=1e-7 * np.max(np.abs(Phi[0])))
    assert np.max(np.abs(Phi[-1])) < 1e-3
    assert np.all(np.asarray(traj.aux.rank) == 2) and bool(traj.healthy)


def _claims_own_system(ns):
    _claims_engine(ns)
    # the page's puck is examples/loops/puck.py as written there, it is in the registry, and
    # its engine holds the puck on the 0.5 m circle (the puck's distance from the centre)
    import jax

    from vcjax import loops
    from vcjax.rollout import RolloutConfig

    puck_block = blocks(ROOT / "docs" / "guides" / "own-system.md", "python")[1]
    assert puck_block.strip() in (ROOT / "examples" / "loops" / "puck.py").read_text()
    loop = loops.make_loop("puck", "vcm")
    sc = loops.make_scenario(loop)
    tr = jax.jit(lambda g: loops.simulate(loop, g, sc, RolloutConfig(num_steps=400), 0.02))(
        loop.default_gains()
    )
    pos = np.asarray(loop.signals(tr, sc).pos)
    assert abs(np.hypot(pos[0, 0], pos[0, 1]) - 0.5) > 0.05  # it starts off the circle
    assert abs(np.hypot(pos[-1, 0], pos[-1, 1]) - 0.5) < 1e-3


def _claims_sweeps(ns):
    # the medians per current-speed bin equal those computed with NumPy from the raw values
    ds = ns["ds"]
    assert dict(ds["iae_e"].sizes) == {"variant": 2, "scenario": 8}
    speed = np.asarray(ds["current_speed"].values)
    iae = np.asarray(ds["iae_e"].sel(variant="alos").values)
    by_bin = np.asarray(ns["by_speed"].sel(variant="alos").values)
    for k, (lo, hi) in enumerate([(0.0, 0.5), (0.5, 1.0)]):
        sel = (speed > lo) & (speed <= hi)
        if sel.any():
            assert by_bin[k] == np.median(iae[sel])
    assert ds["iae_e"].attrs["units"] == "m s"


def _claims_method(ns):
    # a spline "through waypoints, parametrised by cumulative chord length": the frame at each
    # knot is the waypoint, and psi_p is the direction of a finite difference
    from vcjax.paths import path_frame

    pts = np.array([[0, 0], [20, 5], [35, 30], [20, 55]], float)
    knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    for w, pt in zip(knots, pts, strict=True):
        f = path_frame(ns["path"], ns["coeffs"], w)
        np.testing.assert_allclose(np.asarray(f.p_bar), pt, atol=1e-9)
    h = 1e-5
    a, b = (np.asarray(path_frame(ns["path"], ns["coeffs"], 12.0 + d).p_bar) for d in (-h, h))
    psi_fd = np.arctan2(b[1] - a[1], b[0] - a[0])
    assert abs(float(ns["frame"].psi_p) - psi_fd) < 1e-6


def _claims_vehicles(ns):
    # REMUS 100 replay: every state finite, (501, 6) poses, and the actuator states follow PVS's
    # Euler lag exactly: a_k = a_cmd (1 - (1 - dt/T)^k) from 0 (fins 0.1 s, propeller 1 s)
    rep = ns["rep"]
    assert bool(rep.ok.all()) and rep.x.eta.shape == (501, 6)
    assert np.all(np.isfinite(np.asarray(rep.x.nu)))
    cmd = np.array([np.radians(5.0), np.radians(-5.0), 1525.0])
    T = np.array([0.1, 0.1, 1.0])
    expected = cmd * (1.0 - (1.0 - 0.02 / T) ** 500)
    np.testing.assert_allclose(np.asarray(rep.x.act[-1]), expected, rtol=1e-9)


def _claims_waves(ns):
    # "this sea's own Hs" is near the asked 2 m (64 components: 1.5 % scatter), and the orbital
    # velocity 5 m deep is Airy's sum recomputed here with NumPy from the sea's arrays
    assert abs(float(ns["hs"]) - 2.0) < 0.1
    s = {k: np.asarray(v, np.float64) for k, v in ns["waves"].sea_state(
        __import__("jax").random.PRNGKey(0), 2.0, 8.0, np.pi / 2)._asdict().items()}  # fmt: skip
    th = s["wavenumber"] * (0.0 * np.cos(s["direction"])) - s["omega"] * 10.0 + s["phase"]
    amp = s["amplitude"] * s["omega"] * np.exp(-s["wavenumber"] * 5.0)
    u = [np.sum(amp * np.cos(th) * np.cos(s["direction"])),
         np.sum(amp * np.cos(th) * np.sin(s["direction"])), -np.sum(amp * np.sin(th))]  # fmt: skip
    np.testing.assert_allclose(np.asarray(ns["u"]), u, atol=1e-12)
    # the scenario carries the sea and its origin depth
    sc = ns["sc"]
    np.testing.assert_array_equal(np.asarray(sc.sea.phase), np.asarray(ns["sea"].phase))
    assert float(sc.origin_depth) == 2.0


def _claims_gpu(ns):
    import jax

    assert jax.default_backend() in {"cpu", "gpu", "cuda", "rocm", "tpu"}


def _claims_disturbances(ns):
    import jax

    from vcjax import environment, loops

    assert "tidal" in environment.components()
    assert all(np.isfinite(np.asarray(a)).all() for a in jax.tree_util.tree_leaves(ns["traj"].x))
    assert ns["train"].environment.params[0].speed.shape == (4,)
    with pytest.raises(ValueError, match="^tidal: the odin loop cannot take a time-varying"):
        loops.check_environment(loops.make_loop("odin", "vcm"), ns["env"])


CLAIMS = {
    "README.md": _claims_first_loop,
    "docs/getting-started.md": _claims_first_loop,
    "docs/guides/own-system.md": _claims_own_system,
    "docs/guides/sweeps.md": _claims_sweeps,
    "docs/method.md": _claims_method,
    "docs/reference/vehicles.md": _claims_vehicles,
    "docs/guides/gpu.md": _claims_gpu,
    "docs/guides/waves.md": _claims_waves,
    "docs/guides/disturbances.md": _claims_disturbances,
}


@pytest.mark.parametrize("page", PY_PAGES, ids=_rel)
def test_python_blocks_run_and_their_claims_hold(page):
    assert _rel(page) in CLAIMS, f"{_rel(page)}: a page with Python gets its claims checked here"
    from vcjax.environment import component as env_registry
    from vcjax.loops import registry

    # a page registers its example loop (or disturbance) as a reader's fresh session would:
    # take out what an earlier test registered under the same names (a taken name is refused)
    saved = dict(registry._REGISTRY)
    saved_env = dict(env_registry._REGISTRY)
    registry._REGISTRY.pop("puck", None)
    env_registry._REGISTRY.pop("tidal", None)
    try:  # the claims too: they may look up what the page registered
        CLAIMS[_rel(page)](run_page(page))
    finally:
        registry._REGISTRY.clear()
        registry._REGISTRY.update(saved)
        env_registry._REGISTRY.clear()
        env_registry._REGISTRY.update(saved_env)


def test_the_readme_example_is_the_getting_started_example():
    (readme,) = blocks(README, "python")
    assert readme in blocks(ROOT / "docs" / "getting-started.md", "python")


# --------------------------------------------------------------------------- shell blocks


def _command_lines(code: str):
    """Logical command lines of a bash block (continuations joined, comments dropped)."""
    code = code.replace("\\\n", " ")
    for line in code.splitlines():
        line = shlex.join(shlex.split(line, comments=True))
        if line:
            for part in line.split(" && "):
                yield part.strip()


def _strip_prefix(tokens: list[str]) -> list[str]:
    """Drop ``VAR=value`` assignments and launchers (``srun ...``) before the command."""
    while tokens and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", tokens[0]):
        tokens = tokens[1:]
    if tokens and tokens[0] == "srun":
        tokens = tokens[next(i for i, t in enumerate(tokens) if t.endswith("vcjax")) :]
    return tokens


OUTPUT_FLAGS = {"--out", "--json", "-d", "-o"}


def _repo_paths(tokens):
    """Repository files a command reads (not the ones it writes: after ``--out``, ``--json``)."""
    return [
        t
        for prev, t in zip(["", *tokens[:-1]], tokens, strict=True)
        if prev not in OUTPUT_FLAGS and re.match(r"(examples|benchmarks|tests|docs)/\S+\.\w+$", t)
    ]


def _help_text(argv: list[str]) -> str:
    r = subprocess.run(
        [sys.executable, *argv, "--help"], capture_output=True, text=True, cwd=ROOT, timeout=300
    )
    assert r.returncode == 0, f"{argv}: --help failed: {r.stderr[-500:]}"
    return r.stdout


SHELL = [(p, line) for p in PAGES for code in blocks(p, "bash") for line in _command_lines(code)]


def test_shell_blocks_name_real_commands_and_flags():
    from vcjax.cli import build_parser

    parser = build_parser()
    helps: dict[tuple, str] = {}
    checked = 0
    for page, line in SHELL:
        tokens = _strip_prefix(shlex.split(line))
        where = f"{_rel(page)}: {line}"
        cmd = Path(tokens[0]).name
        for path in _repo_paths(tokens):
            assert (ROOT / path).exists(), f"{where}: {path} does not exist"
        if cmd == "vcjax":
            try:
                parser.parse_args(tokens[1:])
            except SystemExit as err:
                raise AssertionError(f"{where}: the vcjax parser refuses it") from err
        elif cmd in ("python", "python3") and tokens[1:2] == ["-m"] and tokens[2] != "venv":
            mod = tokens[2]
            assert importlib.util.find_spec(mod) is not None, f"{where}: no module {mod}"
            key = ("-m", mod)
            helps.setdefault(key, _help_text(["-m", mod]) if mod != "pytest" else "")
            for flag in (t.split("=")[0] for t in tokens[3:] if t.startswith("--")):
                assert mod == "pytest" or flag in helps[key], f"{where}: {mod} has no {flag}"
        elif cmd in ("python", "python3") and tokens[1].endswith(".py"):
            key = (tokens[1],)
            helps.setdefault(key, _help_text([tokens[1]]))
            for flag in (t.split("=")[0] for t in tokens[2:] if t.startswith("--")):
                assert flag in helps[key], f"{where}: {tokens[1]} has no {flag}"
        elif cmd in ("pip", "ruff", "mkdocs", "source", "bash", "python3", "nvidia-smi"):
            pass  # installers and tools: the set-up test and CI run these
        else:
            raise AssertionError(f"{where}: unknown command {cmd!r}: teach this test to check it")
        checked += 1
    assert checked >= 20


# --------------------------------------------------------------------------- links


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_links_and_images_stay_inside_the_repository(page):
    text = FENCE.sub("", page.read_text())
    for target in LINK.findall(text):
        if re.match(r"https?://", target):
            assert not re.match(r"https?://(localhost|127\.|0\.0\.0\.0|10\.|192\.168\.)", target)
            continue
        assert not target.startswith("/"), f"{_rel(page)}: absolute link {target}"
        path = target.split("#")[0]
        if not path:
            continue
        dest = (page.parent / path).resolve()
        generated = page.parent.name == "docs" and path.startswith(("api/", "benchmarks/"))
        assert generated or dest.exists(), f"{_rel(page)}: broken link {target}"
        assert generated or ROOT in dest.parents, f"{_rel(page)}: {target} leaves the repository"


def test_nothing_refers_outside_the_repository():
    tracked = subprocess.run(
        ["git", "ls-files"], capture_output=True, text=True, cwd=ROOT, check=True
    ).stdout.split()
    bad = []
    needle = "../" + "shared"
    for name in tracked:
        p = ROOT / name
        if p.suffix in {".py", ".md", ".toml", ".ipynb", ".yml", ".txt", ".cfg"} and p.is_file():
            if needle in p.read_text(errors="ignore"):
                bad.append(name)
    assert not bad, f"files referring outside the repository: {bad}"


def test_the_config_reference_lists_every_key_of_every_command():
    """The reference is generated from the parsers' schemas: every key of every section of
    ``sweep``, ``tune`` and ``fit`` appears, with a description (a key added without one fails)."""
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import _hooks
    finally:
        sys.path.pop(0)
    text = _hooks.config_reference()
    from vcjax.config import schema

    for sec, spec in schema().items():
        assert f"[{sec}]" in text
        for key, meta in spec["keys"].items():
            # open keys (the vehicle's [initial] keys, a loop's options) are one row in italics
            assert f"| {key} |" in text or meta.get("open_keys") or meta["type"] == "options", (
                sec,
                key,
            )
    for sections in _hooks.command_sections().values():
        for sec, keys in sections.items():
            assert f"[{sec}]" in text
            for key in keys:
                assert f"| {key} |" in text, (sec, key)


# --------------------------------------------------------------------------- README and CI


def test_readme_is_short_and_its_commands_are_what_ci_runs():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    first, second = blocks(README, "bash")[:2]
    install = [ln for ln in first.splitlines() if ln and not ln.startswith("#")][0]
    test_cmd = [ln for ln in second.splitlines() if ln and not ln.startswith("#")][0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci
    assert install.split(" && ")[:2] == [
        "python3 -m venv .venv",
        '.venv/bin/pip install -e ".[test]"',
    ]
    assert '.venv/bin/pip install -q -e ".[test]"' in ci
    assert "mkdocs build --strict" in ci
    assert not re.search(r"\bissue[- ]\d", text) and "until 20" not in text


# slow: .ci/run builds the site with `mkdocs build --strict` itself (asserted above), so the
# default run need not build it a second time
@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="docs extra not installed")
def test_site_builds_strict(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"},
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "site" / "reference" / "config" / "index.html").exists()
    assert (tmp_path / "site" / "api" / "vcjax.rollout" / "index.html").exists()
