"""Logs for the `vcjax fit` examples.

    python examples/fit/make_logs.py remus-noisy --out out/logs     # PVS log + sensor noise
    python examples/fit/make_logs.py infante --out out/infante      # "true" INFANTE-class plant

``remus-noisy`` adds white Gaussian noise to PythonVehicleSimulator's REMUS 100 log
(``tests/data/remus100_pvs_reference.csv``): 2 cm on positions, 0.1 deg on angles and fins,
1 cm/s on velocities, 0.1 deg/s on rates, 2 rpm on the propeller (seed 1).

``infante`` builds the "true" INFANTE-class plant with the coefficients of
``vcjax.identify.manoeuvres.STUDY_PARAMS`` off by +-20 % from the nominal ones (signs from
``--seed``), logs a 20/20 zig-zag, a turning circle and speed steps (120 s each, 10 Hz, rk4) with
``SENSOR_NOISE``, and writes ``true_params.json`` (a flat {name: value} map, usable as
``[scenario] plant_params``) and ``nominal_params.json`` next to them.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def remus_noisy(out: Path, seed: int) -> None:
    from vcjax.identify import get_fit_model, load_log, save_log_csv

    model = get_fit_model("remus100")
    log = load_log(
        ROOT / "tests/data/remus100_pvs_reference.csv", model.state_columns, model.command_columns
    )
    sig = np.array(
        [0.02] * 3 + [math.radians(0.1)] * 3 + [0.01] * 3 + [math.radians(0.1)] * 3
        + [math.radians(0.1)] * 2 + [2.0]
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    x = log.x + rng.normal(size=log.x.shape) * sig
    out.mkdir(parents=True, exist_ok=True)
    path = save_log_csv(
        out / "remus100_pvs_noisy.csv", log.t, x, log.u, model.state_columns,
        model.command_columns,
        provenance=f"{log.provenance}; + white noise {sig.tolist()} (seed {seed})",
    )  # fmt: skip
    print(f"wrote {path}")


def infante(out: Path, seed: int) -> None:
    from vcjax.identify import get_fit_model
    from vcjax.identify.manoeuvres import STUDY_PARAMS, infante_logs, perturbed_params

    model = get_fit_model("infante")
    nominal = model.nominal(None)
    true = perturbed_params(nominal, 0.2, seed=seed)
    files = infante_logs(true, out, seed=seed)
    for name, p in (("true_params.json", true), ("nominal_params.json", nominal)):
        values = {n: float(getattr(p, n)) for n in STUDY_PARAMS}
        (out / name).write_text(json.dumps(values, indent=2) + "\n")
        files.append(out / name)
    for f in files:
        print(f"wrote {f}")


def main() -> None:
    jax.config.update("jax_enable_x64", True)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("which", choices=["remus-noisy", "infante"])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args()
    (remus_noisy if a.which == "remus-noisy" else infante)(Path(a.out), a.seed)


if __name__ == "__main__":
    main()
