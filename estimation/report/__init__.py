"""What ``estimate`` writes: the table, ``estimate.json``, the history, the report's figures
and page, and the Rerun recording.
"""

__all__: list[str] = []
