"""The tab's two docked panels survive an exercise switch.

Removing the chart panel and docking a new one at every switch raced in the
browser's dock layout: now and then the new panel came up at the default
width (~300 px, tabs wrapped, y labels cut: issue 11, defect 2) or not at
all.  A panel whose last tab goes leaves the layout, and its successor
is docked as a new column at the default width.  The lab therefore docks its
panels and their tabs once per browser tab and swaps only the tabs' contents.
``clear`` does what ``gui.reset()`` does (elements of the main panel, modals,
commands) but keeps the given panels and tabs.
"""

from __future__ import annotations


def clear(gui, keep: tuple) -> None:
    """Remove every GUI element of this tab except the panels and tabs in ``keep``
    (the tabs' contents go): the dock layout never sees a panel without tabs."""
    root = gui._container_handle_from_uuid["root"]
    while root._children:
        next(iter(root._children.values())).remove()
    while gui._handles_in_foreign_containers:
        next(iter(gui._handles_in_foreign_containers.values())).remove()
    while gui._modal_handle_from_uuid:
        next(iter(gui._modal_handle_from_uuid.values())).close()
    kept = {id(handle) for handle in keep}
    for panel in tuple(gui._panel_handle_from_uuid.values()):
        if id(panel) not in kept:
            panel.remove()
            continue
        for tab in tuple(panel._tab_handles):
            if id(tab) not in kept:
                tab.remove()
                continue
            for child in tuple(tab._children.values()):
                child.remove()
    while gui._command_handle_from_uuid:
        next(iter(gui._command_handle_from_uuid.values())).remove()
