"""What a process's tabs may upload at once (the recordings a student loads as CSV).

A browser sends a file as one ``FileTransferStartUpload`` that declares its size, then its
parts; viser buffers the parts until the last one.  ``app/infra/traffic.py`` asks ``Uploads``
before it passes either on: a declared size above ``MAX_UPLOAD_BYTES`` is refused before any
part, parts beyond the declared size end the upload, a tab has at most one unfinished upload
(a new one drops the older), the unfinished uploads of the process may declare at most
``UPLOAD_BUDGET_BYTES`` together, and one that sends no part for ``UPLOAD_STALE_S`` is dropped.
What ``Uploads`` drops, the caller frees in viser (``viser_internals.forget_upload``)."""

from __future__ import annotations

from dataclasses import dataclass

#: Largest upload accepted (the recordings' limit) [bytes].
MAX_UPLOAD_BYTES = 20_000_000
#: What the unfinished uploads of one process may declare together (five of the largest at once) [bytes].
UPLOAD_BUDGET_BYTES = 100_000_000
#: An unfinished upload that sends no part for this long is dropped [s] (a browser sends every
#: part at once: 20 MB take 16 s on a 10 Mbit/s link).
UPLOAD_STALE_S = 30.0


def describe_bytes(size: float) -> str:
    """A size for the student, in MB."""
    return f"{size / 1e6:.1f} MB"


@dataclass
class Transfer:
    """One unfinished upload: bytes declared and received, and when its last part came [s]."""

    declared: int
    received: int = 0
    last_part: float = 0.0


class Uploads:
    """The unfinished uploads of one process, by (client id, transfer uuid): at most one per tab,
    at most ``budget`` bytes declared in all, none idle longer than ``stale_s``."""

    def __init__(self, budget: int = UPLOAD_BUDGET_BYTES, stale_s: float = UPLOAD_STALE_S):
        self.budget, self.stale_s = budget, stale_s
        self.transfers: dict[tuple, Transfer] = {}

    def reserved(self) -> int:
        return sum(t.declared for t in self.transfers.values())

    def start(self, client_id, transfer: str, declared: int, now: float) -> tuple[bool, list[tuple]]:
        """A tab starts an upload: whether it is accepted, and the (client, transfer) pairs dropped
        for it (the tab's older unfinished upload, stale ones), whose parts must be freed."""
        dropped = [key for key in self.transfers if key[0] == client_id] + self.stale(now)
        for key in dropped:
            self.transfers.pop(key, None)
        accepted = self.reserved() + declared <= self.budget
        if accepted:
            self.transfers[(client_id, transfer)] = Transfer(declared, 0, now)
        return accepted, dropped

    def part(self, client_id, transfer: str, size: int, now: float) -> str | None:
        """A part arrived: "more" (pass it on), "done" (pass it on, the upload is complete),
        "overflow" (beyond the declared size: the upload is dropped) or None (not a transfer
        in progress: ignore it)."""
        key = (client_id, transfer)
        current = self.transfers.get(key)
        if current is None:
            return None
        if current.received + size > current.declared:
            del self.transfers[key]
            return "overflow"
        current.received += size
        current.last_part = now
        if current.received == current.declared:
            del self.transfers[key]
            return "done"
        return "more"

    def stale(self, now: float) -> list[tuple]:
        return [key for key, t in self.transfers.items() if now - t.last_part > self.stale_s]

    def drop(self, keys) -> None:
        for key in keys:
            self.transfers.pop(key, None)

    def of_client(self, client_id) -> list[tuple]:
        return [key for key in self.transfers if key[0] == client_id]
