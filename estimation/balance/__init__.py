"""balance."""

__all__: list[str] = []
