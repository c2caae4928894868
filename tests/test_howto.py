"""The how-to examples run as the guides say: a law of your own (``examples/laws/los_pd.py``)
swept beside a built-in law and tuned, through the command line a user types (the configs of
``examples/sweeps/own_law.toml`` and ``examples/tuning/own_law.toml``), and through Python."""

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import cli, loops
from vcjax.config.scenario import import_module_file
from vcjax.sweep.run import variant_gains

ROOT = Path(__file__).resolve().parents[1]


def test_own_law_swept_beside_a_builtin_law(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "sweep"
    assert cli.main(["sweep", str(ROOT / "examples/sweeps/own_law.toml"), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert set(s["variants"]) == {"los_pd", "vcm_integral"}
    # each law ran with its own gains type (the LOS-PD law's are not the VCM's), and both keep
    # the craft on the line in these currents
    for v in ("los_pd", "vcm_integral"):
        assert s["variants"][v]["n_diverged"] == 0
        assert s["variants"][v]["metrics"]["ss_abs_e"]["p95"] < 5.0


def test_own_law_tuned_from_its_config(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "tune"
    assert cli.main(["tune", str(ROOT / "examples/tuning/own_law.toml"), "--out", str(out)]) == 0
    gains = json.loads((out / "gains.json").read_text())
    assert {"Delta", "sigma", "k_u", "k_p", "k_d"} <= set(
        json.dumps(gains).replace('"', " ").split()
    )
    s = json.loads((out / "summary.json").read_text())
    assert np.isfinite(s["heldout_loss_after"]) and s["heldout_loss_after"] > 0


def test_own_law_in_python(monkeypatch):
    """The guide's Python block, run as written from the repository root."""
    import re

    page = (ROOT / "docs/guides/own-law.md").read_text()
    code = re.findall(r"^```py\n(.*?)^```$", page, flags=re.S | re.M)[-1]
    monkeypatch.chdir(ROOT)
    ns: dict = {}
    exec(compile(code, "own-law.md", "exec"), ns)
    e = np.asarray(ns["e"])
    # the craft starts 10 m off the line x = 10 m and the law brings it closer
    assert abs(e[0]) > 9.0 and abs(e[-1]) < 0.5 * abs(e[0])
    assert ns["loop"].controller == "los_pd"


def test_variant_gains_refuses_gains_of_another_law():
    import_module_file(ROOT / "examples/laws/los_pd.py")
    ls = {v: loops.make_loop("infante", v) for v in ("los_pd", "vcm_integral")}
    vcm = ls["vcm_integral"].default_gains()
    g = variant_gains(ls, vcm)
    assert g["vcm_integral"] is vcm and type(g["los_pd"]).__name__ == "LosPDGains"
    with pytest.raises(ValueError, match="los_pd"):
        variant_gains(ls, {"los_pd": vcm})
    with pytest.raises(ValueError, match="no variant"):
        variant_gains(ls, {"nope": vcm})
    los = ls["los_pd"].default_gains()._replace(Delta=jnp.asarray(3.0))
    assert float(variant_gains(ls, los)["los_pd"].Delta) == 3.0


def test_the_guide_shows_the_example_as_it_is():
    page = (ROOT / "docs/guides/own-law.md").read_text()
    law = (ROOT / "examples/laws/los_pd.py").read_text().rstrip()
    assert f"```py\n{law}\n```" in page
    toml = (ROOT / "examples/sweeps/own_law.toml").read_text().split("\n\n", 1)[1].rstrip()
    assert toml in page


def test_the_disturbance_guide_shows_the_example_component_as_it_is():
    import re

    page = (ROOT / "docs/guides/disturbances.md").read_text()
    shown = re.findall(r"^```python\n(.*?)^```", page, flags=re.S | re.M)[0]
    assert shown.strip() in (ROOT / "examples/environment/tidal.py").read_text()
