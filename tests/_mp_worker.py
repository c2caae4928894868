"""Worker of tests/test_distributed.py, started as one of several real processes by
``vcjax.runtime.distributed.spawn``: joins the run, builds the tuning problem of a config file, shards its
training batch over the global mesh (what ``vcjax tune`` does) and writes the loss and gradient,
with the gains shared and tiled per scenario, and how often three tuner steps compiled the step.

    python tests/_mp_worker.py CONFIG.toml OUT_DIR
"""

import dataclasses
import json
import sys
from pathlib import Path

from vcjax.runtime import distributed
from vcjax.runtime.compiler import prefer_fast_compile

prefer_fast_compile()  # as the CLI does, before JAX starts
distributed.initialize_from_env()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
distributed.warm_up()

import numpy as np  # noqa: E402

from tuning.config import load_config  # noqa: E402
from tuning.loss import objective  # noqa: E402
from tuning.optim import make_optimizer, make_step, run_gradient_tuner  # noqa: E402
from tuning.run import build, distribute  # noqa: E402


def main(config, out):
    problem, _, data, train, _ = build(load_config(config))
    train, data, theta = distribute(train, data, data.theta_ref)
    loss, grad = jax.jit(jax.value_and_grad(lambda th, d, s: objective(th, d, s, problem)[0]))(
        theta, data, train
    )
    shards = {str(s.device) for s in train.eta0.addressable_shards}
    rec = {
        "process": jax.process_index(),
        "processes": jax.process_count(),
        "devices": jax.device_count(),
        "local_rows": sum(s.data.shape[0] for s in train.eta0.addressable_shards),
        "shard_devices": sorted(shards),
        "loss": float(np.asarray(loss)),
        "grad": np.asarray(grad).tolist(),
    }
    # what ``vcjax tune`` runs on a sharded batch: tiled gains, the jitted step compiled once
    tiled = dataclasses.replace(problem, tile_gains=True)
    lf = lambda th, d, s: objective(th, d, s, tiled)[0]
    step = make_step(lf, make_optimizer("lbfgs", 0.05, 10, 15), "lbfgs")
    loss_t, grad_t = step.value_and_grad(theta, (data, train))  # the step's own program
    res = run_gradient_tuner(lf, theta, (data, train), steps=3, step_fn=step)
    rec.update(
        loss_tiled=float(np.asarray(loss_t)),
        grad_tiled=np.asarray(grad_t).tolist(),
        step_compiles=step._cache_size(),
        tuned_loss=float(res.loss),
    )
    Path(out, f"proc{jax.process_index()}.json").write_text(json.dumps(rec))


if __name__ == "__main__":
    main(*sys.argv[1:3])
