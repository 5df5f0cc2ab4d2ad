"""The one module of the app that touches viser's private names (checked by ruff's SLF001
everywhere else).  Pinned to the viser minor release the tests run on (pyproject.toml):
re-check each function here on an upgrade."""

from __future__ import annotations


def send_data(handle, data: tuple) -> None:
    """Set a uPlot chart's columns and send them as they are: the handle's public ``data``
    setter casts every column to float64 (twice the bytes of the float32 the scope sends)."""
    handle._impl.props.data = data
    handle._queue_update("data", data)


def gui_input_handle(server, client_id: int | None, uuid: str):
    """The handle of the control a client's GUI update addresses (its own or a shared one), or None."""
    client = server._connected_clients.get(client_id)
    return getattr(client, "gui", server.gui)._gui_input_handle_from_uuid.get(uuid)


def forget_upload(server, client_id: int | None, transfer: str) -> None:
    """Drop the parts viser buffers of an unfinished upload (it keeps them until the last part)."""
    client = server._connected_clients.get(client_id)
    for gui in (server.gui, getattr(client, "gui", None)):
        if gui is not None:
            gui._current_file_upload_states.pop(transfer, None)


def element_id(handle) -> str:
    """The id viser gives a GUI element: its page-side ``<label for=...>`` carries it."""
    return handle._impl.uuid
