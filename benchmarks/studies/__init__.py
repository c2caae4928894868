"""Studies: questions answered by running the library many times (e.g. which tuner reaches the
lowest held-out loss for a given rollout budget), not by timing it."""
