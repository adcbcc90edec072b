"""The information-gathering planner (paper Sections "Motion Planning" to "Pruning")."""

__all__: list[str] = []
