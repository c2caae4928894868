"""The kernel counter of ``tests/reference/hlo.py`` (kernels per step of a compiled ``while``
body; ``benchmarks/perf/cost_analysis.py`` reports it), checked on programs whose kernels are known: an elementwise scan body fuses
into one kernel with no library call; a ``vmap``-ed 6x6 ``jnp.linalg.solve`` in the body puts
LAPACK custom calls there; ``linalg.solve_small``, the unrolled replacement, puts none."""

import jax
import jax.numpy as jnp

from tests.reference.hlo import while_body_kernels
from vcjax import linalg


def _scan_text(body, x0):
    def run(x):
        return jax.lax.scan(lambda c, _: (body(c), None), x, None, length=50)[0]

    return jax.jit(run).lower(x0).compile().as_text()


def test_elementwise_body_is_one_fusion_without_library_calls():
    k = while_body_kernels(_scan_text(lambda x: jnp.sin(x) * 2.0 + 1.0, jnp.ones(64)))
    assert k["total"] >= 1
    assert k.get("custom-call", 0) == 0
    assert k.get("fusion", 0) >= 1


def test_batched_lapack_solve_shows_custom_calls_and_unrolled_solve_none():
    a = jnp.eye(6) * 3.0 + 0.1 * jnp.arange(36.0).reshape(6, 6) / 36.0
    x0 = jnp.ones((32, 6))

    def lapack(x):
        return jax.vmap(lambda b: jnp.linalg.solve(a + jnp.diag(b) * 0.01, b))(x)

    def unrolled(x):
        return jax.vmap(lambda b: linalg.solve_small(a + jnp.diag(b) * 0.01, b))(x)

    assert while_body_kernels(_scan_text(lapack, x0)).get("custom-call", 0) >= 1
    k = while_body_kernels(_scan_text(unrolled, x0))
    assert k.get("custom-call", 0) == 0 and k["total"] >= 1


def test_no_while_loop_counts_nothing():
    text = jax.jit(lambda x: x * 2.0).lower(jnp.ones(3)).compile().as_text()
    assert while_body_kernels(text) == {"total": 0}
