"""Errors the plant raises: each names the problem, so a caller (an FMU, a scenario)
can report it instead of propagating NaN."""


class PlantError(ValueError):
    """Base class of every error raised by plant models."""


class InvalidInputError(PlantError):
    """Wrong shape, NaN or inf in an argument."""


class UnreachablePoseError(PlantError):
    """The legs (or sliders) cannot reach the requested pose or input."""


class SingularConfigurationError(PlantError):
    """The configuration is (numerically) singular: forces or motion are undefined."""


class ConvergenceError(PlantError):
    """An iterative solve (Newton, an integrator) did not converge."""


class StrokeError(PlantError):
    """A leg left its stroke (actuator length range)."""


class WorkBoundError(PlantError):
    """A step would take more substeps than one call may (integrators.MAX_SUBSTEPS): it is
    refused at once rather than run for hours or overflow a count."""
