"""Post-flight estimation: log readers, the parameter EKF, noise fit and batch refinement."""
