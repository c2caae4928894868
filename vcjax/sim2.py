"""Compatibility name of :mod:`vcjax.experiments.sim2` (the same module object), kept for
scripts and notebooks written before the experiments registry; new code imports the
experiment through :mod:`vcjax.experiments` (only the CLI does, inside vcjax)."""

import sys

from vcjax.experiments import sim2

sys.modules[__name__] = sim2
