"""The simulation's state under its Run / Pause / Reset buttons: running, paused or stopped
(with a card when it stops), and how fast it runs."""

from __future__ import annotations

import re

from app.panels.live import SpeedMeter

RUNNING, PAUSED = "**Running**", "**Paused**"


#: a simulation's own stop message: "Stopped at t = 12.0 ms: the rotor touched down. …"
STOPPED_AT = re.compile(r"^Stopped (at [^:]+): ")


def stopped(message: str) -> str:
    """The status line of a stopped run, always "Stopped: …": a message that already says so is not
    prefixed again ("Stopped: Stopped at t = …" was the issue), "Stopped at t = 12.0 ms: reason"
    reads "Stopped: at t = 12.0 ms, reason"."""
    if message.startswith("Stopped:"):
        said = message
    elif STOPPED_AT.match(message):
        said = STOPPED_AT.sub(r"Stopped: \1, ", message, count=1)
    else:
        said = f"Stopped: {message}"
    return f"**{said}** Press Run or Reset to start again."


class SimulationStatus:
    """The status line and speed line of one exercise, and the tab's one 'Simulation stopped' card."""

    def __init__(self, client):
        self.client = client
        self.line = None                          # running / paused / stopped
        self.speed = None                         # × real time, filled in while it runs
        self.meter = SpeedMeter()
        self.card = None

    def add_line(self, gui) -> None:
        self.line = gui.add_markdown(RUNNING)

    def add_speed(self, gui) -> None:
        self.speed, self.meter = gui.add_markdown(""), SpeedMeter()

    def notify_stop(self, message: str) -> None:
        """One 'Simulation stopped' card at a time: a new stop replaces the last card."""
        self.clear_card()
        self.card = self.client.add_notification("Simulation stopped", message, color="red",
                                                 auto_close_seconds=10.0)

    def clear_card(self) -> None:
        if self.card is not None:
            self.card.remove()
            self.card = None
