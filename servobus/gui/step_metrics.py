"""The step figures live in :mod:`servobus.axis.step_metrics` (shared with ``servobus tune``)."""

from servobus.axis.step_metrics import StepMetrics, step_metrics

__all__ = ["StepMetrics", "step_metrics"]
