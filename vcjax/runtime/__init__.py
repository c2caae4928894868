"""Runtime plumbing under the commands: devices and sharding (:mod:`~vcjax.runtime.devices`),
multi-process runs (:mod:`~vcjax.runtime.distributed`), the persistent compilation cache
(:mod:`~vcjax.runtime.cache`) and XLA flags (:mod:`~vcjax.runtime.compiler`), output folders,
manifests and locks (:mod:`~vcjax.runtime.outputs`), Ctrl-C handling
(:mod:`~vcjax.runtime.interrupts`), size estimates (:mod:`~vcjax.runtime.sizing`), progress
lines (:mod:`~vcjax.runtime.progress`) and what ran (:mod:`~vcjax.runtime.runinfo`).

Nothing here knows physics; the modules are imported by name (``from vcjax.runtime import
outputs``), and this package imports none of them itself.
"""
