"""Runtime plumbing under the commands: devices and sharding ([`devices`][vcjax.runtime.devices]),
multi-process runs ([`distributed`][vcjax.runtime.distributed]), the persistent compilation cache
([`cache`][vcjax.runtime.cache]) and XLA flags ([`compiler`][vcjax.runtime.compiler]), output
folders,
manifests and locks ([`outputs`][vcjax.runtime.outputs]), Ctrl-C handling
(``interrupts``), size estimates ([`sizing`][vcjax.runtime.sizing]), progress
lines ([`progress`][vcjax.runtime.progress]) and what ran ([`runinfo`][vcjax.runtime.runinfo]).

Nothing here knows physics; the modules are imported by name (``from vcjax.runtime import
outputs``), and this package imports none of them itself.
"""
