"""The page around the lab's panels: the browser tab's title, viser's notices kept off the
controls on any screen from 1024 x 768 to 1920 x 1080, and exercise titles that fit the chooser
(issue 25)."""

from __future__ import annotations

import html

LAB_NAME = "AMB estimation lab"
#: Below this window width the gap between the docked controls (380 px) and charts (600 px) is
#: narrower than a notice (20 em): viser's notices would cover the charts' tabs and block clicks
#: there, so they are not shown; the lab says the same in its status line under Run/Pause/Reset.
NARROW_WINDOW_PX = 1300

STYLE = f"""<style>
/* viser's "Software WebGL rendering detected" notice: the lab's 3D view already refreshes once a
   second by default (its hint says why), and the notice sat over the charts' tabs until closed */
#webgl-software-rendering {{ display: none !important; }}
@media (max-width: {NARROW_WINDOW_PX - 1}px) {{
  .mantine-Notifications-root {{ display: none !important; }}
}}
/* the exercise chooser's list is as wide as its titles, which wrap instead of being cut */
.mantine-Select-dropdown {{ min-width: 22rem !important; }}
.mantine-Select-option {{ white-space: normal; line-height: 1.25; }}
</style>"""


def title_markdown(exercise_title: str) -> str:
    """A Markdown element that names the browser tab "AMB estimation lab — <exercise>" (viser's
    page says "Viser"): React hoists a ``title`` element rendered anywhere into the head."""
    return f"<title>{LAB_NAME} — {html.escape(exercise_title)}</title>"
