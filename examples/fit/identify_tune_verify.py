"""Identify -> tune -> verify on the INFANTE-class craft, as a sequence of `vcjax` commands.

    python examples/fit/identify_tune_verify.py --out out/study

1. a "true" plant: eight hydrodynamic coefficients +-20 % off the nominal ones; a zig-zag, a
   turning circle and speed steps logged from it with sensor noise
   (``examples/fit/make_logs.py infante``);
2. ``vcjax fit``: the eight coefficients identified from the logs, starting from the nominal model;
3. ``vcjax tune`` twice, on the same random scenarios (Simulation 1's line, random currents up
   to 0.5 m/s and initial offsets; trained with the hard-clipped actuators the evaluation uses):
   on the nominal model, and on the identified model (``[scenario] params = fit.json``: plant
   and controller design model);
4. verify on the true plant (``[scenario] plant_params = true_params.json``, the same held-out
   scenarios for every row): ``vcjax tune`` with ``initial_gains`` set to the gains under test
   reports their held-out loss as ``heldout_loss_before`` (its one optimiser step is ignored).
   The controller's design model is the one each row was tuned with.

Every config is written into ``OUT`` (printed), so each step can be re-run by hand. The table
goes to stdout and to ``OUT/study.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

TUNE = """\
[scenario]
vehicle = "infante"
controller = "vcm_integral"
{scenario}
[problem]
horizon = {horizon}
dt = 0.1
smooth = false
{problem}
[scenarios]
current_max = {current_max}

[train]
size = {train}
seed = 0

[heldout]
size = {heldout}
seed = 1001

[optimizer]
name = "lbfgs"
steps = {steps}

[report]
plot_scenarios = 3
"""

FIT = """\
[data]
files = ["logs/infante_zigzag.csv", "logs/infante_turning_circle.csv",
         "logs/infante_speed_steps.csv"]

[model]
vehicle = "infante"
step = "rk4"

[fit]
params = ["X_uu", "Y_uv", "Y_ur", "N_uv", "N_ur", "Y_uudr", "N_uudr", "cf_coeff"]
initial_scale = 1.0
segment_steps = 50
max_iters = 50
"""


def vcjax(*args: str) -> None:
    cmd = [sys.executable, "-m", "vcjax.cli", *args]
    print("$ vcjax " + " ".join(args), flush=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/study")
    ap.add_argument("--seed", type=int, default=1, help="signs of the true plant's errors")
    ap.add_argument("--horizon", type=float, default=60.0)
    ap.add_argument("--train", type=int, default=16)
    ap.add_argument("--current-max", type=float, default=0.5, help="[m/s]")
    ap.add_argument("--heldout", type=int, default=32)
    ap.add_argument("--steps", type=int, default=20)
    a = ap.parse_args()
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    sizes = dict(horizon=a.horizon, train=a.train, heldout=a.heldout, current_max=a.current_max)

    # 1. logs from the true plant
    subprocess.run(
        [sys.executable, str(HERE / "make_logs.py"), "infante", "--out", str(out / "logs"),
         "--seed", str(a.seed)],
        check=True,
    )  # fmt: skip
    true_params = out / "logs" / "true_params.json"

    # 2. identify
    (out / "fit.toml").write_text(FIT)
    vcjax("fit", str(out / "fit.toml"), "--out", str(out / "fit"), "--quiet", "--overwrite")
    fit_json = out / "fit" / "fit.json"

    # 3. tune on the nominal and on the identified model
    def tune(name, scenario="", problem="", steps=a.steps):
        cfg = out / f"{name}.toml"
        cfg.write_text(TUNE.format(scenario=scenario, problem=problem, steps=steps, **sizes))
        vcjax("tune", str(cfg), "--out", str(out / name), "--overwrite")
        return json.loads((out / name / "summary.json").read_text())

    identified = f'params = "{fit_json}"'
    tune("tune_nominal")
    tune("tune_identified", scenario=identified)

    # 4. verify on the true plant
    plant = f'plant_params = "{true_params}"'
    rows = {
        "default gains, nominal design model": ("", ""),
        "tuned on the nominal model": ("", out / "tune_nominal" / "gains.json"),
        "default gains, identified design model": (identified, ""),
        "tuned on the identified model": (identified, out / "tune_identified" / "gains.json"),
    }
    table = {}
    for i, (label, (design, gains)) in enumerate(rows.items()):
        problem = f'initial_gains = "{gains}"' if gains else ""
        s = tune(f"verify_{i}", scenario=f"{design}\n{plant}", problem=problem, steps=1)
        table[label] = s["heldout_loss_before"]
    ref = table["default gains, nominal design model"]
    print(f"\nheld-out loss on the TRUE plant ({a.heldout} scenarios, {a.horizon:g} s):")
    for label, loss in table.items():
        print(f"  {label:<42} {loss:10.5g}  ({100 * (loss / ref - 1):+.1f} % vs default)")
    fit = json.loads(fit_json.read_text())
    true = json.loads(true_params.read_text())
    result = {
        "heldout_loss_true_plant": table,
        "fit": {
            n: {"true": true[n], "nominal": fit["nominal"][n], "estimate": v, "std": fit["std"][n]}
            for n, v in fit["estimates"].items()
        },  # fmt: skip
        "settings": vars(a),
    }
    (out / "study.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out / 'study.json'}")


if __name__ == "__main__":
    main()
