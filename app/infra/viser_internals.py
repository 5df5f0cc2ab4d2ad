"""The one module of the app that touches viser's private names (checked by ruff's SLF001
everywhere else).  Pinned to the viser minor release the tests run on (pyproject.toml):
re-check each function here on an upgrade."""

from __future__ import annotations


def send_data(handle, data: tuple) -> None:
    """Set a uPlot chart's columns and send them as they are: the handle's public ``data``
    setter casts every column to float64 (twice the bytes of the float32 the scope sends)."""
    handle._impl.props.data = data
    handle._queue_update("data", data)
