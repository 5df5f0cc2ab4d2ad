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


# -- which panel tab the browser shows ------------------------------------------------------------
#: Labels of a panel tab's two hidden beacon buttons (``visibility_beacon``), followed by the tab's name.
SHOWN_LABEL, HIDDEN_LABEL = "panel shown:", "panel hidden:"
#: Runs once when the beacon's HTML is inserted (as an image's error handler: viser sets the HTML as
#: ``innerHTML``, which never runs a script): hides the two buttons' boxes (their padding would leave a
#: gap), then watches the element's size: viser keeps a visited panel tab in the page with
#: ``display: none`` while another tab is shown, so its width is 0 exactly while hidden.  The first
#: change from hidden (the assumption) is reported at once.
_BEACON_SCRIPT = ("var e=this.parentNode,s=false;if(!e)return;"
                  "['{shown}','{hidden}'].forEach(function(i){var b=document.getElementById(i);"
                  "if(b&&b.parentNode)b.parentNode.style.display='none'});"
                  "var o=new ResizeObserver(function(){if(!e.isConnected){o.disconnect();return}"
                  "var v=e.offsetWidth>0;if(v!==s){s=v;var b=document.getElementById(v?'{shown}':'{hidden}');"
                  "if(b)b.click()}});o.observe(e)")


def visibility_beacon(gui, name: str, on_shown, on_hidden) -> None:
    """Call ``on_shown`` / ``on_hidden`` (viser click callbacks) when the panel tab this is added to
    (inside its ``with``) is shown or hidden in the browser.

    viser sends no message when the student picks a panel tab: the tab strip is the browser's own
    state.  Each tab therefore carries two hidden buttons and a small script that watches whether
    the tab is displayed and clicks the matching button, so the news travels through viser's own
    button events on the tab's websocket.  Private to viser's client: a button's DOM id is its
    handle's uuid and its box is the button's parent, an HTML element's event handler attributes
    run, and a hidden panel tab stays in the page with ``display: none``.  Headless clients report a
    tab by sending the click of the button labelled ``SHOWN_LABEL`` + the tab's name."""
    shown = gui.add_button(f"{SHOWN_LABEL} {name}")
    hidden = gui.add_button(f"{HIDDEN_LABEL} {name}")
    shown.on_click(on_shown)
    hidden.on_click(on_hidden)
    ids = (element_id(shown), element_id(hidden))
    script = _BEACON_SCRIPT.replace("{shown}", ids[0]).replace("{hidden}", ids[1])
    hide = ",".join(f'[id="{uuid}"]' for uuid in ids)   # at once, before the script hides their boxes
    gui.add_html(f'<style>{hide}{{display:none}}</style>'
                 f'<img alt="" style="display:none" src="data:," onerror="{script}">')
