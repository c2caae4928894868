"""Test configuration: float64 and strict dtype promotion for every test.

The library itself never flips these switches; only the tests do.
"""

import os

import jax

# the CLI turns on JAX's persistent compilation cache (vcjax.cache); tests run in-process or
# in subprocesses must never read or fill the user's cache folder
os.environ["VCJAX_CACHE_DIR"] = "off"

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
