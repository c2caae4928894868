"""vcjax's benchmarks, by question: ``perf/`` (how fast), ``compare/`` (git A/B comparisons),
``studies/``; shared helpers in :mod:`benchmarks._common`; results in ``benchmarks/results/``.
One entry point: ``python -m benchmarks`` (:mod:`benchmarks.__main__`) lists and runs them."""
