"""Errors raised by the DMP core: both are ValueErrors with a message meant for users."""


class DemonstrationError(ValueError):
    """A demonstration is empty, malformed, too short, non-finite or otherwise unusable."""


class GeneralizationError(ValueError):
    """A generalization request cannot be served (bad start, goal, obstacles; degeneracy)."""
