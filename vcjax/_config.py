"""Former home of the config helpers: they live in :mod:`vcjax.config` (re-exported here)."""

from vcjax.config.values import *  # noqa: F403
from vcjax.config.values import __all__  # noqa: F401
