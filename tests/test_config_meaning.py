"""One bound per value and no silent change of meaning (issue: reliability round 3): seeds are
checked against the range the sampler uses, through the CLI and the Python API; a default means
the same written or omitted; old and new spellings that disagree are refused naming both; a key
that does not apply is refused; a gains file is refused for another vehicle or controller."""

from __future__ import annotations

import numpy as np
import pytest

from vcjax import cli
from vcjax.config import SEED_MAX, ConfigError, as_seed


def _run(argv, capsys) -> tuple[int, str]:
    rc = cli.main(argv)
    return rc, capsys.readouterr().err


# ------------------------------------------------------------------ seeds


@pytest.mark.parametrize("seed", [-1, 2**32, 2**63 - 1, 2**63])
def test_seed_outside_the_sampler_range_is_refused_by_the_python_api(seed):
    from tuning.scenarios import sample_scenarios as tune_samples
    from vcjax.sweep import ScenarioSpec, SweepSpec, sample_scenarios

    msg = f"seed: {seed} is outside the seed range 0 .. {SEED_MAX}"
    with pytest.raises(ConfigError, match=msg):
        SweepSpec(num_scenarios=1, seed=seed)
    with pytest.raises(ConfigError, match=msg):
        sample_scenarios(ScenarioSpec(), seed, np.arange(1))
    with pytest.raises(ValueError, match=msg):
        tune_samples(seed, 1)


@pytest.mark.parametrize("v", [True, 1.0, "3", None])
def test_seed_must_be_an_integer(v):
    with pytest.raises(ConfigError, match="x: expected an integer seed"):
        as_seed("x", v)


def test_seed_bound_is_the_sampler_key_type():
    """SEED_MAX is the largest uint32 (what the sampler's key is built from), accepted; one more
    does not fit the key type at all."""
    import jax.numpy as jnp

    assert as_seed("s", SEED_MAX) == SEED_MAX == int(jnp.iinfo(jnp.uint32).max)
    assert as_seed("s", np.int64(7)) == 7
    with pytest.raises(OverflowError):
        jnp.asarray(SEED_MAX + 1, jnp.uint32)
