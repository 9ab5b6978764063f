"""System identification (issue 3)."""

__all__: list[str] = []
