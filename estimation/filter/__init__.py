"""The paper's parameter EKF, its guard, its maximum-likelihood fits, and the filter pipeline."""

__all__: list[str] = []
