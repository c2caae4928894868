"""What the water and the world do to a vehicle: currents and waves."""

from vcjax.environment import current, waves

__all__ = ["current", "waves"]
