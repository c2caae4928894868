"""Former home of the ``[scenario]`` section: :mod:`vcjax.config.scenario` (re-exported here)."""

from vcjax.config.scenario import *  # noqa: F403
from vcjax.config.scenario import __all__, import_module_file, path_spec  # noqa: F401
