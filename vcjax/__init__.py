"""vcjax: virtually constrained motion control of underwater vehicles, in JAX."""
