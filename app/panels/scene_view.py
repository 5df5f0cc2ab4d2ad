"""The 3D view between the docked panels: how often it follows the simulation."""

from __future__ import annotations

import time

#: 3D view refresh periods [s] (None: still).  Every scene change makes the viser client
#: render for 250 ms, so anything faster than 4/s renders non-stop: fine on a GPU, but in
#: software WebGL it starves the page (slider-to-readout latency 0.6 s instead of 0.15 s).
SCENE_REFRESH = {"1 update/s": 1.0, "10 updates/s (needs a GPU)": 0.1, "still": None}
SCENE_QUIET_AFTER_INPUT_S = 0.5   # the 3D view holds still this long after a control moves: readouts first
#: Narrowest 3D view shown, as width / height of the gap between the docked panels: the scenes are
#: framed for 386 x 768 px (``scenes.bearing.CANVAS_PX``) and lose the bearing's sides below about
#: 310 px; at 1024 x 768 the gap is viser's smallest, 120 px, and the view would be a cut-off strip.
MIN_SCENE_ASPECT = 0.4
HIDDEN_NOTE = ("*Hidden: this window leaves the 3D view too little room between the panels. Widen the "
               "window or zoom the page out (Ctrl −) to see it.*")


class SceneView:
    """One tab's 3D view pacing: the student's refresh choice (kept across exercises) and a
    quiet spell after every control move, so the readouts go out first."""

    def __init__(self):
        self.refresh = next(iter(SCENE_REFRESH))
        self.quiet_until = 0.0                    # perf_counter time before which the view waits
        self.hidden = False                       # the window leaves the view no room (``fit``)
        self.note = None                          # says so under the dropdown

    def add_control(self, gui, on) -> None:
        """The "3D view" dropdown; ``on(key, action)`` makes its GUI callback."""
        dropdown = gui.add_dropdown("3D view", tuple(SCENE_REFRESH), initial_value=self.refresh,
                                    hint="How often the 3D view follows the simulation. Smooth motion needs "
                                         "a graphics card; without one it slows the whole page.")
        dropdown.on_update(on("3D view", lambda: setattr(self, "refresh", dropdown.value)))
        self.note = gui.add_markdown(HIDDEN_NOTE, visible=self.hidden)

    def fit(self, scene_api, width_px: int, height_px: int, attached: bool = False) -> None:
        """The browser reported the 3D view's size (0: not yet): fold the view away while it is too
        narrow to show the scene (a cut-off strip at 1024 px), show it again once there is room; a
        message only when that changes, or for a scene just ``attached`` (it starts visible).  Call
        holding the tab's GUI lock."""
        hidden = width_px / height_px < MIN_SCENE_ASPECT if width_px > 0 and height_px > 0 else self.hidden
        if hidden != self.hidden or attached and hidden:
            scene_api.set_global_visibility(not hidden)
        self.hidden = hidden
        if self.note is not None and self.note.visible != hidden:
            self.note.visible = hidden

    def hold(self) -> None:
        """A control moved: the view waits ``SCENE_QUIET_AFTER_INPUT_S``."""
        self.quiet_until = time.perf_counter() + SCENE_QUIET_AFTER_INPUT_S

    def due(self, now: float, next_at: float) -> bool:
        """Whether the view should follow at ``now``, its frame ticker's next time being ``next_at``."""
        period = SCENE_REFRESH[self.refresh]
        return period is not None and not self.hidden and now >= max(next_at, self.quiet_until)

    def period_s(self) -> float | None:
        return SCENE_REFRESH[self.refresh]
