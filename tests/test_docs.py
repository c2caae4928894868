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
#: a fenced block: the closing fence alone on its line (text glued to it would swallow what follows)
FENCE = re.compile(r"^```(\w*)\n(.*?)^```[ \t]*$", flags=re.S | re.M)


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
    saved_env = dict(env_registry.REGISTRY)
    registry._REGISTRY.pop("puck", None)
    env_registry.REGISTRY.pop("tidal", None)
    try:  # the claims too: they may look up what the page registered
        CLAIMS[_rel(page)](run_page(page))
    finally:
        registry._REGISTRY.clear()
        registry._REGISTRY.update(saved)
        env_registry.REGISTRY.clear()
        env_registry.REGISTRY.update(saved_env)


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


# --------------------------------------------------------------------------- shown configs

#: the command that reads each folder of example configs
CONFIG_COMMANDS = {"sweeps": "sweep", "tuning": "tune", "fit": "fit", "falsify": "falsify"}
EXAMPLE_CONFIGS = sorted((ROOT / "examples").rglob("*.toml"))


def _check_config(command: str, path: Path) -> None:
    """Parse and check ``path`` with the command's own loader: nothing is simulated, compiled
    or fitted (a ``ConfigError`` naming the key if the command would refuse it)."""
    if command == "sweep":
        from vcjax.sweep.config import load_config

        load_config(path)
    elif command == "falsify":
        from vcjax.search.config import load_config

        load_config(path)
    elif command == "tune":
        from tuning.config import load_config

        load_config(path)
    else:
        from vcjax.identify.config import load_fit_config

        load_fit_config(path)


def test_every_example_config_is_in_a_folder_of_its_command():
    assert EXAMPLE_CONFIGS
    for path in EXAMPLE_CONFIGS:
        assert path.parent.name in CONFIG_COMMANDS, f"{_rel(path)}: which command reads it?"


@pytest.fixture
def own_registry(monkeypatch):
    """Loops, laws and disturbances a config's ``[scenario] module`` registers stay inside the
    test."""
    from vcjax.config import scenario
    from vcjax.environment import component as env_registry
    from vcjax.loops import registry

    monkeypatch.setattr(env_registry, "REGISTRY", dict(env_registry.REGISTRY))
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    for cls in set(registry._REGISTRY.values()):
        monkeypatch.setattr(cls, "laws", cls.laws)
        monkeypatch.setattr(cls, "controllers", cls.controllers)
    monkeypatch.setattr(scenario, "_IMPORTED", dict(scenario._IMPORTED))


@pytest.mark.parametrize("path", EXAMPLE_CONFIGS, ids=_rel)
def test_example_configs_pass_their_commands_checks(path, own_registry):
    _check_config(CONFIG_COMMANDS[path.parent.name], path)


def test_a_config_its_command_refuses_fails_the_check(tmp_path, own_registry):
    """The check above can fail: a shipped config with one wrong key is refused by each
    command's loader, naming the key."""
    from vcjax.config import ConfigError

    for folder, command in CONFIG_COMMANDS.items():
        src = next(p for p in EXAMPLE_CONFIGS if p.parent.name == folder)
        bad = tmp_path / folder / src.name
        bad.parent.mkdir()
        bad.write_text(src.read_text() + "\n[no_such_section]\nkey = 1\n")
        with pytest.raises(ConfigError, match="no_such_section"):
            _check_config(command, bad)


def _config_argument(tokens: list[str]) -> tuple[str, str] | None:
    """``(command, config)`` of a ``vcjax sweep|tune|fit CONFIG`` line (also under ``launch``)."""
    if "--" in tokens:
        tokens = tokens[tokens.index("--") + 1 :]
    else:
        tokens = tokens[1:]
    if not tokens or tokens[0] not in ("sweep", "tune", "fit"):
        return None
    return tokens[0], next(t for t in tokens[1:] if not t.startswith("-"))


def test_command_lines_name_an_existing_config_of_their_command():
    """Every ``vcjax sweep|tune|fit`` line of a page names a shipped config in that command's
    folder of ``examples/`` (checked above by the command's loader), or a placeholder in
    capitals (``CONFIG``)."""
    named = set()
    for page, line in SHELL:
        tokens = _strip_prefix(shlex.split(line))
        if Path(tokens[0]).name != "vcjax" or not (found := _config_argument(tokens)):
            continue
        command, config = found
        where = f"{_rel(page)}: {line}"
        if config.isupper():
            continue
        folder = {v: k for k, v in CONFIG_COMMANDS.items()}[command]
        assert config.startswith(f"examples/{folder}/"), f"{where}: not a config of {command}"
        assert (ROOT / config).is_file(), f"{where}: {config} does not exist"
        named.add(config)
    assert {"examples/sweeps/quick.toml", "examples/tuning/acceptance.toml"} <= named
    assert any(c.startswith("examples/fit/") for c in named)


def _is_part(shown, full) -> bool:
    """Every key of ``shown`` (nested tables included) has the same value in ``full``."""
    if isinstance(shown, dict):
        return isinstance(full, dict) and all(
            k in full and _is_part(v, full[k]) for k, v in shown.items()
        )
    return shown == full


TOML_BLOCKS = [(p, code) for p in PAGES for code in blocks(p, "toml")]


@pytest.mark.parametrize(
    "page, code", TOML_BLOCKS, ids=[f"{_rel(p)}:{i}" for i, (p, _) in enumerate(TOML_BLOCKS)]
)
def test_shown_toml_is_part_of_a_shipped_config(page, code):
    """A TOML block on a page sets nothing that a shipped example config does not set to the
    same value, so the loader checks above cover what the page shows (a block cannot drift
    from the file it quotes, nor show a key or value the command would refuse)."""
    import tomllib

    shown = tomllib.loads(code)
    assert shown, f"{_rel(page)}: an empty TOML block"
    files = [p for p in EXAMPLE_CONFIGS if _is_part(shown, tomllib.loads(p.read_text()))]
    assert files, f"{_rel(page)}: a TOML block is not part of any examples/**/*.toml"


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
    assert '.venv/bin/pip install -q -c .ci/tools.txt -e ".[test]"' in ci
    assert "mkdocs build --strict" in ci
    # not quiet: `-q` lowers the log level below warnings, and strict mode then passes a site
    # with broken cross-references (it did: 29 warnings went unseen)
    assert not re.search(r"mkdocs build[^\n]*\s-q\b", ci)
    assert not re.search(r"\bissue[- ]\d", text) and "until 20" not in text


# slow: .ci/run builds the site with `mkdocs build --strict` itself (asserted above), so the
# default run need not build it a second time
@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="docs extra not installed")
def test_site_builds_strict(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"},
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert "WARNING" not in r.stderr, r.stderr[-3000:]
    assert (tmp_path / "site" / "reference" / "config" / "index.html").exists()
    assert (tmp_path / "site" / "api" / "rollouts" / "index.html").exists()


# --------------------------------------------------------------------------- rendering


def _line_headings(text: str) -> list[str]:
    """Headings as the lines say (outside fenced blocks, a fence toggled by a line that starts
    with three backticks)."""
    out, fenced = [], False
    for ln in text.splitlines():
        if ln.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"#{1,6} ", ln):
            out.append(ln.split(" ", 1)[1].strip())
    return out


def _rendered_headings(text: str) -> list[str]:
    """Headings as a CommonMark parser renders them."""
    from markdown_it import MarkdownIt

    tokens = MarkdownIt("commonmark").parse(text)
    return [tokens[i + 1].content for i, t in enumerate(tokens) if t.type == "heading_open"]


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_page_renders_its_headings(page):
    """Every heading written on a page is a heading once rendered: a fence with text glued to
    its closing backticks (or left open) swallows what follows it into a code block."""
    text = page.read_text()
    assert _rendered_headings(text) == _line_headings(text)


def test_readme_renders_as_intended():
    heads = _rendered_headings(README.read_text())
    assert heads[0] == "vcjax"
    for h in ("Set up", "A closed loop in Python", "Sweep, then tune", "Documentation", "Citing"):
        assert h in heads, (h, heads)


def test_the_rendering_check_catches_a_glued_fence():
    bad = "# t\n\n```bash\nx\n``` text glued\n\n## Swallowed\n"
    assert _rendered_headings(bad) != _line_headings(bad)


# --------------------------------------------------------------------------- release


def test_release_files_agree():
    """A lab can install and cite: a licence, a citation whose version is the package's (one
    source: ``vcjax.__version__``, read by the build), type information shipped."""
    import tomllib

    import vcjax

    assert "MIT License" in (ROOT / "LICENSE").read_text()
    cff = (ROOT / "CITATION.cff").read_text()
    assert re.search(rf'^version: "?{re.escape(vcjax.__version__)}"?$', cff, flags=re.M)
    assert re.search(r"^cff-version: 1\.2\.0$", cff, flags=re.M)
    assert re.search(r"^license: MIT$", cff, flags=re.M)
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in project["project"] and project["project"]["dynamic"] == ["version"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "vcjax.__version__"}
    assert (ROOT / "vcjax" / "py.typed").exists()
    assert "py.typed" in project["tool"]["setuptools"]["package-data"]["vcjax"]
    assert "bash .ci/package" in (ROOT / ".ci" / "run").read_text()
    log = (ROOT / "docs" / "changelog.md").read_text()  # Keep a Changelog
    assert "\n## [Unreleased]\n" in log
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d\d-\d\d)$", log, flags=re.M)
    assert released and released[0][0] == vcjax.__version__
    assert re.search(rf'^date-released: "?{released[0][1]}"?$', cff, flags=re.M)
    head = log.split("\n## [", 3)[2]  # the newest release's section
    assert "### Added" in head and "### Fixed" in head


def test_pages_name_the_packages_version():
    """Where a user page names the version to cite or install, it is the package's."""
    import vcjax

    for page in ("docs/index.md", "docs/getting-started.md"):
        text = (ROOT / page).read_text()
        named = set(re.findall(r"version (\d+\.\d+\.\d+)", text))
        assert named == {vcjax.__version__}, (page, named)
        assert "MIT licence" in text, page


def test_ci_tools_are_pinned_and_docs_extra_bounded():
    """The tools CI runs are pinned exactly; the docs extra has upper bounds (a new major of the
    docstring parser must not turn a clean checkout red)."""
    import tomllib

    pins = [
        ln
        for ln in (ROOT / ".ci" / "tools.txt").read_text().splitlines()
        if ln and not ln.startswith("#")
    ]
    assert pins and all(re.fullmatch(r"[A-Za-z0-9_.\-]+==[0-9][0-9A-Za-z.]*", p) for p in pins)
    names = {p.split("==")[0] for p in pins}
    assert {"ruff", "pytest", "mkdocs", "mkdocstrings-python", "griffelib"} <= names
    docs = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert all("<" in req for req in docs["docs"]), docs["docs"]


def test_cli_reference_is_generated_from_the_parser():
    """The command-line reference lists every option of every command, straight from the
    parser (options added later cannot be missing: simulate --max-steps, demo --horizon and
    launch --port once were)."""
    import argparse

    from vcjax.cli import build_parser

    assert "<!-- vcjax:cli-reference -->" in (ROOT / "docs/reference/cli.md").read_text()
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import _hooks
    finally:
        sys.path.pop(0)
    text = _hooks.cli_reference()

    def walk(parser, name):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub in action.choices.items():
                    yield f"{name} {sub_name}", sub
                    yield from walk(sub, f"{name} {sub_name}")

    commands = list(walk(build_parser(), "vcjax"))
    assert {"vcjax simulate", "vcjax sweep", "vcjax tune", "vcjax fit", "vcjax launch"} <= {
        n for n, _ in commands
    }
    for name, sub in commands:
        section = text.split(f"`{name}`", 1)[1]
        for action in sub._actions:
            for flag in action.option_strings:
                if flag not in ("-h", "--help") and action.help != argparse.SUPPRESS:
                    assert f"`{flag}" in section or f", {flag}" in section, (name, flag)
    for name, flag in [("launch", "--port"), ("demo", "--horizon"), ("simulate", "--max-steps")]:
        assert f"`{flag}" in text.split(f"`vcjax {name}`", 1)[1], (name, flag)


# --------------------------------------------------------------------------- quoted results

#: numbers user pages quote from committed result files: (page, results file, key path,
#: format); the formatted value must appear on the page, so a re-made result that moves a
#: number fails here until the page says the new one
SWEEP = ("docs/guides/sweeps.md", "docs/figures/sweep/summary.json")
TUNE = ("docs/guides/tuning.md", "docs/figures/tune/summary.json")
REMUS = ("docs/experiments/remus100.md", "docs/figures/remus100/metrics.json")
SIM1 = ("docs/experiments/sim1.md", "docs/figures/sim1/metrics.json")
SIM1X = ("docs/experiments/sim1.md", "docs/figures/sim1_cross_current/metrics.json")
SIM1_LAWS = ("vcm", "vcm_integral", "ilos", "los_pid", "vcm_ilos", "alos")
SIM2 = ("docs/experiments/sim2.md", "docs/figures/sim2/metrics.json")
REMUS_LAWS = ("vcm3d_ilos", "vcm3d", "decoupled", "alos3d", "pvs_pid")
OWN = "docs/guides/own-system.md"
FIT = ("docs/guides/identification.md", "docs/figures/fit/study.json")
STUDY = ("docs/experiments/identify-tune-verify.md", "docs/figures/fit/study.json")
FIT_PARAMS = ("X_uu", "Y_uv", "Y_ur", "N_uv", "N_ur", "Y_uudr", "N_uudr", "cf_coeff")
#: the tuner study's measurement log quotes its result files
TUNERS_STORE = ("docs/development/tuners.md", "benchmarks/results/tuners_remus100_store.json")
TUNERS_SIM2 = ("docs/development/tuners.md", "benchmarks/results/tuners_sim2_store.json")
TUNERS_SEAS = ("docs/development/tuners.md", "benchmarks/results/tuners_remus100_waves_store.json")
QUOTES = [
    (*TUNERS_STORE, "summary.target", "| {:.4f} |"),
    (*TUNERS_STORE, "summary.ratios_wall_s_to_1%.warm: lbfgs/cmaes at 1%", "**{:.2f}**"),
    (*TUNERS_STORE, "summary.ratios_wall_s_to_1%.cold: lbfgs/cmaes at 1%", "| {:.2f} |"),
    (*TUNERS_SIM2, "summary.ratios_wall_s_to_1%.warm: lbfgs/cmaes at 1%", "**{:.2f}**"),
    (*TUNERS_SEAS, "summary.ratios_wall_s_to_1%.warm: lbfgs/cmaes at 1%", "**{:.2f}**"),
    (*SWEEP, "variants.vcm.metrics.ss_abs_e.p50", "{:.2f} m"),
    (*SWEEP, "variants.ilos.metrics.ss_abs_e.p50", "{:.3f} m"),
    (*SWEEP, "variants.los_pid.metrics.ss_abs_e.p50", "{:.2f} m"),
    (*SWEEP, "variants.vcm_ilos.metrics.ss_abs_e.p50", "{:.3f} m"),
    (*SWEEP, "variants.alos.metrics.ss_abs_e.p50", "{:.3f} m"),
    (*SWEEP, "variants.alos.metrics.ss_abs_e.p95", "p95 {:.2f} m"),
    (*TUNE, "heldout_loss_before", "| {:.2f} |"),
    (*TUNE, "heldout_loss_after", "| {:.2f} |"),
    (*TUNE, "heldout_reduction_pct", "−{:.1f} %"),
    (*TUNE, "heldout_terms_before.eps", "| {:.2f} |"),
    (*TUNE, "heldout_terms_after.eps", "| {:.2f} |"),
    (*TUNE, "heldout_terms_before.sat_excess", "| {:.2f} |"),
    (*REMUS, "variants.decoupled.ss_dist_3d", "{:.3f} m"),
    (*REMUS, "variants.decoupled.ss_cross_track", "{:.3f} m"),
    (*REMUS, "variants.vcm3d_ilos.ss_dist_3d", "{:.3f} m"),
    (*REMUS, "variants.alos3d.ss_dist_3d", "{:.3f} m"),
    *[
        (*REMUS, f"variants.{v}.{k}", "| {:.3g} m |")
        for v in REMUS_LAWS
        for k in ("rms_dist_3d", "max_dist_3d")
    ],
    *[(*SIM1, f"{v}.ss_abs_e", "| {:.1e} |") for v in SIM1_LAWS if v != "los_pid"],
    (*SIM1, "los_pid.ss_abs_e", "| {:.2f} |"),
    *[
        (*run, f"{v}.{k}", fmt)
        for run in (SIM1, SIM1X)
        for v in SIM1_LAWS
        for k, fmt in (
            ("iae_e", "| {:.1f} |"),
            ("max_abs_tau_u", "| {:.1f} |"),
            ("sat_fraction", "| {:.3f} |"),
        )
    ],
    *[(*SIM1X, f"{v}.ss_abs_e", "| {:.1e} |") for v in ("ilos", "vcm_ilos", "alos")],
    (*SIM1X, "los_pid.ss_abs_e", "| {:.2f} |"),
    (*SIM1X, "vcm.ss_abs_e", "{:.2f} m (`vcm`)"),
    (*SIM1X, "vcm_integral.ss_abs_e", "{:.2f} m (`vcm_integral`)"),
    *[
        (*SIM2, f"by_actuation.{a}.{k}", fmt)
        for a in ("underactuated", "full")
        for k, fmt in (
            ("rms_dist_3d", "{:.2f} /"),
            ("max_dist_3d", "/ {:.2f} m"),
            ("mean_abs_sideslip_deg", "{:.1f}°"),
        )
    ],
    *[
        (OWN, f"docs/figures/sweep_{s}/summary.json", f"variants.{v}.metrics.ss_abs_e.{q}", fmt)
        for s in ("circle", "survey")
        for v in ("vcm_integral", "vcm_ilos", "ilos")
        for q, fmt in (("p50", "| {:.3f} ("), ("p95", "({:.2f}) |"))
    ],
    *[(*FIT, f"fit.{p}.{k}", "| {:.6g} |") for p in FIT_PARAMS for k in ("true", "estimate")],
    *[(*FIT, f"fit.{p}.std", "| {:.2g} |") for p in FIT_PARAMS],
    (*STUDY, "heldout_loss_true_plant.default gains, nominal design model", "| {:.2f} |"),
    (*STUDY, "heldout_loss_true_plant.tuned on the nominal model", "| {:.2f} |"),
    (*STUDY, "heldout_loss_true_plant.default gains, identified design model", "| {:.2f} |"),
    (*STUDY, "heldout_loss_true_plant.tuned on the identified model", "| **{:.2f}** |"),
]


@pytest.mark.parametrize("page, results, key, fmt", QUOTES, ids=lambda x: str(x)[-40:])
def test_pages_quote_the_committed_results(page, results, key, fmt):
    import json

    value = json.loads((ROOT / results).read_text())
    for part in key.split("."):
        value = value[part]
    quoted = fmt.format(value)
    text = (ROOT / page).read_text()
    # a page may typeset a negative number with the minus sign
    assert quoted in text or quoted.replace("-", "\N{MINUS SIGN}") in text, (page, key, quoted)


def test_the_registered_loops_table_lists_every_loop():
    from vcjax import loops

    page = (ROOT / "docs/guides/own-system.md").read_text()
    rows = {ln.split("|")[1].split("`")[1]: ln for ln in page.splitlines() if ln.startswith("| `")}
    for v in ("infante", "odin", "arm", "remus100"):
        assert v in rows, v
        cls = loops.loop_class(v)
        for c in loops.controllers(v):
            if c in cls.laws and not type(cls.laws[c]).__module__.startswith("vcjax."):
                continue  # a law an example or a test registered in this process
            assert f"`{c}`" in rows[v], (v, c)


def test_docstrings_cross_reference_in_markdown():
    """Docstrings link with the cross-references mkdocstrings resolves (``[name][path]``), not
    Sphinx roles, which the site would print literally and link nowhere."""
    role = re.compile(r":(func|class|mod|meth|data|attr|exc|obj):`")
    bad = [
        f"{_rel(p)}:{i}"
        for pkg in ("vcjax", "tuning")
        for p in sorted((ROOT / pkg).rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), start=1)
        if role.search(line)
    ]
    assert not bad, bad[:10]
