"""The batch MAP refinement: states and θ jointly over the whole flight, by multiple shooting."""

__all__: list[str] = []
