"""The Pole map tab's "Show mode" dropdown (issue 11, defect 15).

viser's uPlot takes no JavaScript callbacks (``cursor.dataIdx``, ``legend.values`` and
``cursor.move`` are functions in uPlot), and its live legend shows only the Im s of each
series at the row under the cursor, not which mode a point is.  So the student picks a mode
here instead: it is ringed on both maps (a legend entry names it) and its name, s, f_n, ζ
and state participation are shown below; the ring follows the mode (by set and name) when
a slider moves it.
"""

from __future__ import annotations

from app.panels import pole_map
from lab_modules.evaluation.poles import PoleView


class ModePicker:
    """The dropdown and the mode's read-out; ``draw`` puts a pole view on the maps."""

    def __init__(self, gui, plots, pole_view: PoleView):
        self.plots, self.view, self.mode = plots, pole_view, None
        self.dropdown = gui.add_dropdown("Show mode", pole_map.mode_choices(pole_view),
                                         initial_value=pole_map.NO_MODE,
                                         hint="Ring one mode on both pole maps and read its name, f_n, ζ and "
                                              "which states take part in it.")
        self.detail = gui.add_markdown(pole_map.detail_markdown(None))

    def pick(self, choice: str) -> None:
        """The student chose ``choice`` (call with the GUI lock held)."""
        self.mode = pole_map.chosen(self.view, choice)
        self._redraw()

    def draw(self, pole_view: PoleView) -> None:
        """Show a new pole view (call with the GUI lock held, inside ``client.atomic``)."""
        self.view = pole_view
        self.mode = pole_map.follow(pole_view, self.mode)
        choices = pole_map.mode_choices(pole_view)
        if tuple(self.dropdown.options) != choices:
            self.dropdown.options = choices
        value = pole_map.NO_MODE if self.mode is None else pole_map.mode_choice(self.mode)
        if self.dropdown.value != value:
            self.dropdown.value = value
        self._redraw()

    def _redraw(self) -> None:
        for handle, (data, options) in zip(self.plots, pole_map.charts(self.view, self.mode)):
            handle.series, handle.axes, handle.data = options["series"], options["axes"], data
            handle.scales, handle.title = options["scales"], options["title"]
        self.detail.content = pole_map.detail_markdown(self.mode)
