"""Compatibility name of :mod:`vcjax.experiments.arm` (the same module object), kept for
scripts and notebooks written before the experiments registry; new code imports the
experiment through :mod:`vcjax.experiments` (only the CLI does, inside vcjax)."""

import sys

from vcjax.experiments import arm

sys.modules[__name__] = arm
