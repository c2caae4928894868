"""Worker of tests/test_distributed.py, started as one of several real processes by
``vcjax.distributed.spawn``: joins the run, builds the tuning problem of a config file, shards its
training batch over the global mesh (what ``vcjax tune`` does) and writes the loss and gradient.

    python tests/_mp_worker.py CONFIG.toml OUT_DIR
"""

import json
import sys
from pathlib import Path

from vcjax import distributed

distributed.initialize_from_env()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
distributed.warm_up()

import numpy as np  # noqa: E402

from tuning.cli import build, distribute  # noqa: E402
from tuning.config import load_config  # noqa: E402
from tuning.loss import objective  # noqa: E402


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
    Path(out, f"proc{jax.process_index()}.json").write_text(json.dumps(rec))


if __name__ == "__main__":
    main(*sys.argv[1:3])
