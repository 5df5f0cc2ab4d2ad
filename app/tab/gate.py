"""The class-token gate: nothing of the lab is built in a tab before its token is right.  Wrong
tries count per tab (``TOKEN_ATTEMPTS``, then the tab is closed) and per client address across
tabs and reconnections (``access.Throttle``)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from app.infra.access import Throttle, token_matches
from app.tab.worker import TabClosed, TabWorker

TOKEN_ATTEMPTS = 5                # wrong class tokens before a tab is disconnected
TOKEN_RETRY_S = 1.0               # a wrong token waits this long before the next try


class TokenGate:
    """One field asking for the class token, and the count of wrong tries."""

    def __init__(self, gui, token: str, worker: TabWorker, enter: Callable[[], None],
                 refuse: Callable[[str], None], tries: Throttle | None = None, address: str = "unknown"):
        """``enter()`` builds the lab once the token is right (on the worker); ``refuse(reason)``
        disconnects the tab after ``TOKEN_ATTEMPTS`` wrong tries; ``tries`` counts the wrong tries
        of the tab's ``address`` across all tabs (beyond its allowance a try is not even checked)."""
        self.token, self.enter, self.refuse = token, enter, refuse
        self.tries, self.address = tries, address
        self.attempts = 0
        self.entered = False
        gui.add_markdown("### AMB estimation lab\nEnter the class token your instructor gave you.")
        self.field = gui.add_text("Class token", "", hint="The token shown by the lab's server at start; "
                                                          "then press Enter the lab.")
        button = gui.add_button("Enter the lab")
        self.message = gui.add_markdown("")
        button.on_click(worker.on("token", self.check))

    def check(self) -> None:
        """The button, not every keystroke, is a try (the field sends each keystroke: a slow
        typist would use up the tries, and free checks per keystroke would invite guessing)."""
        if self.entered:                          # already in (a second click)
            return
        wait_s = self.tries.wait_s(self.address) if self.tries is not None else 0.0
        if wait_s > 0:                            # not checked: a reconnecting guesser learns nothing
            self.message.content = (f"⚠️ Too many wrong class tokens from your network: try again in "
                                    f"{math.ceil(wait_s)} s, or ask your instructor.")
            return
        if token_matches(self.token, self.field.value):
            self.enter()
            self.entered = True
            return
        if self.tries is not None:
            self.tries.failed(self.address)
        self.attempts += 1
        if self.attempts >= TOKEN_ATTEMPTS:
            self.refuse("too many wrong class tokens")
            raise TabClosed
        time.sleep(TOKEN_RETRY_S)                 # guessing costs time; other tabs are not held up
        self.message.content = f"⚠️ That is not the class token ({TOKEN_ATTEMPTS - self.attempts} tries left)."
