"""Test configuration: float64 and strict dtype promotion for every test.

The library itself never flips these switches; only the tests do.
"""

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
