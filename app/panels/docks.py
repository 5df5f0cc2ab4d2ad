"""The two docked panels around the 3D view: the controls (left, viser's main panel) and the
charts (right: Scope / Pole map / Analysis / Worksheet), and the worksheet that can float
over the 3D view instead, beside the charts (self-paced work).  Docked once per tab; an
exercise switch keeps them and refills their tabs."""

from __future__ import annotations

import viser

from lab_modules.scenes.bearing import CANVAS_PX

CONTROL_WIDTH_PX = 380            # the docked controls (left)
PANEL_WIDTH_PX = 600              # the docked charts (right); of 1366 px, 386 stay for the 3D view and the
                                  # notifications (which open there and would otherwise cover the panel's tabs)
PANEL_TABS = (("Scope", viser.Icon.WAVE_SINE), ("Pole map", viser.Icon.CHART_DOTS),
              ("Analysis", viser.Icon.CHART_LINE), ("Worksheet", viser.Icon.NOTEBOOK))


class Docks:
    """One tab's chart panel with its tabs, and the floating worksheet."""

    def __init__(self):
        self.panel = None
        self.beside = None
        self.tabs: dict[str, object] = {}         # panel tab name (and "beside") -> its handle
        self.worksheet_beside = False             # the student's choice, kept across exercises
        self.sheets: dict[str, object] = {}       # "tab" / "beside" -> the worksheet's Markdown (this exercise)

    def add_toggle(self, gui):
        """The checkbox that moves the worksheet beside the charts (in the controls)."""
        return gui.add_checkbox("Worksheet beside the charts", self.worksheet_beside,
                                hint="Show the worksheet in place of the 3D view, next to the scope.")

    def dock(self, gui) -> None:
        """Dock both panels, once per tab (see ``app.infra.layout``)."""
        if self.panel is not None:
            return
        self.panel = gui.add_panel()
        self.tabs = {name: self.panel.add_tab(name, icon) for name, icon in PANEL_TABS}
        gui.main_panel.dock_left()                # both panels docked, the 3D view in between
        gui.main_panel.set_width(CONTROL_WIDTH_PX)
        self.panel.dock_right()
        self.panel.set_width(PANEL_WIDTH_PX)
        self.beside = gui.add_panel(visible=self.worksheet_beside)
        self.tabs["beside"] = self.beside.add_tab("Worksheet", viser.Icon.NOTEBOOK)
        self.beside.float(x=0, y=0, width=CANVAS_PX[0], height=CANVAS_PX[1])   # over the 3D view
        if self.worksheet_beside:
            self.tabs.pop("Worksheet").remove()

    def kept(self) -> tuple:
        """What an exercise switch keeps: the docks themselves."""
        return (self.panel, self.beside, *self.tabs.values())

    def add_worksheets(self, gui, text: str) -> None:
        """The worksheet in its tab (if it is there) and beside the charts."""
        self.sheets = {}
        if "Worksheet" in self.tabs:
            with self.tabs["Worksheet"]:
                self.sheets["tab"] = gui.add_markdown(text)
        with self.tabs["beside"]:
            self.sheets["beside"] = gui.add_markdown(text)

    def show_worksheet(self, text: str) -> None:
        for handle in self.sheets.values():
            handle.content = text

    def put_worksheet_beside(self, gui, beside: bool) -> None:
        """The worksheet is in one place at a time: beside the charts or in their tabs
        (call holding the tab's GUI lock)."""
        self.worksheet_beside = self.beside.visible = beside
        if beside and "Worksheet" in self.tabs:
            self.tabs.pop("Worksheet").remove()
            self.sheets.pop("tab", None)
        elif not beside and "Worksheet" not in self.tabs:
            self.tabs["Worksheet"] = self.panel.add_tab(*PANEL_TABS[-1])
            with self.tabs["Worksheet"]:
                self.sheets["tab"] = gui.add_markdown(self.sheets["beside"].content)
