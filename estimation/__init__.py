"""Post-flight estimation: log readers, the parameter EKF, noise fit and batch refinement."""

__all__: list[str] = []
