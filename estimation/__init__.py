"""Post-flight estimation: log readers and the parameter EKF."""
