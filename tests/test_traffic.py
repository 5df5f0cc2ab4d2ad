"""The wake-up of a connection's writer (``traffic.LoopSideEvent``): a message pushed by another
thread always reaches the writer, also when the push lands between ``Event.wait``'s check of the
flag and its registration of the waiter, where viser's own event loses it for good."""

from __future__ import annotations

import asyncio
import queue
import threading
from typing import Self

import pytest
import viser
import viser._messages as viser_messages
from viser.infra._async_message_buffer import AsyncMessageBuffer

from app.infra import traffic, viser_internals

MESSAGE = viser_messages.GuiUpdateMessage(uuid="scope", updates={"value": 1.0})
WAIT_S = 10.0           # a bound on a wait that ends at once when the writer wakes


class _Writer:
    """A connection's writer (viser's ``_message_producer`` without the socket) on an event loop
    thread of its own: the windows it takes from ``buffer`` arrive in ``windows``."""

    def __init__(self, buffer: AsyncMessageBuffer, loop: asyncio.AbstractEventLoop):
        self.buffer, self.loop = buffer, loop
        self.windows: queue.Queue = queue.Queue()
        self.thread = threading.Thread(target=loop.run_until_complete, args=(self._write(),), daemon=True)

    async def _write(self) -> None:
        async for window in self.buffer.window_generator(0):
            self.windows.put(len(window))

    def __enter__(self) -> Self:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.buffer.set_done()
        self.thread.join(WAIT_S)


def _push_from_a_thread(buffer: AsyncMessageBuffer, atomic: bool = False) -> None:
    """A frame thread's push: alone, or inside an atomic block (as a tab's frame)."""
    def push() -> None:
        if atomic:
            buffer.atomic_start()
        buffer.push(MESSAGE)
        if atomic:
            buffer.atomic_end()
    pusher = threading.Thread(target=push)
    pusher.start()
    pusher.join()


def _pushed_into_the_race(buffer: AsyncMessageBuffer) -> None:
    """Make the next ``Event.wait`` of the writer find the flag down, and let a frame thread push
    right after that check, before the waiter is registered (a GIL switch there does the same)."""
    event = buffer.message_event
    get_loop = event._get_loop                      # called between the check and the registration
    pushed = threading.Event()

    def get_loop_with_a_push_in_between():
        if not pushed.is_set():
            pushed.set()
            _push_from_a_thread(buffer)
        return get_loop()

    event._get_loop = get_loop_with_a_push_in_between


def test_a_push_in_the_race_still_wakes_the_writer():
    traffic.wake_on_the_loop()
    loop = asyncio.new_event_loop()
    buffer = AsyncMessageBuffer(loop, persistent_messages=False)
    assert isinstance(buffer.message_event, traffic.LoopSideEvent)
    _pushed_into_the_race(buffer)
    with _Writer(buffer, loop) as writer:
        assert writer.windows.get(timeout=WAIT_S) == 1


def test_viser_event_loses_the_push_in_the_race():
    """Why ``LoopSideEvent`` exists: with viser's event the writer sleeps on a raised flag with its
    message unsent.  Should this fail after a viser upgrade, viser mended the race itself."""
    loop = asyncio.new_event_loop()
    buffer = AsyncMessageBuffer(loop, persistent_messages=False)
    buffer.message_event = asyncio.Event()
    _pushed_into_the_race(buffer)
    with _Writer(buffer, loop) as writer:
        with pytest.raises(queue.Empty):
            writer.windows.get(timeout=1.0)
        assert buffer.message_event.is_set() and len(buffer.message_event._waiters) == 1
        assert buffer.message_counter == 1 and 0 in buffer.message_from_id     # pushed, never sent


@pytest.mark.parametrize("atomic", [False, True])
def test_every_push_from_another_thread_wakes_the_writer(atomic: bool):
    """``LoopSideEvent`` ignores a set from another thread: viser must set it once more on the loop
    for every push (right away, or at the end of the atomic block)."""
    traffic.wake_on_the_loop()
    loop = asyncio.new_event_loop()
    buffer = AsyncMessageBuffer(loop, persistent_messages=False)
    with _Writer(buffer, loop) as writer:
        for _ in range(20):
            _push_from_a_thread(buffer, atomic)
            assert writer.windows.get(timeout=WAIT_S) == 1


def test_viser_internals_find_a_control_and_free_an_upload():
    """What the upload and update checks touch inside viser (pinned release): a control's handle by
    its uuid, and the parts viser buffers of an unfinished upload, which ``forget_upload`` frees."""
    server = viser.ViserServer(host="127.0.0.1", port=8474, verbose=False)
    try:
        dropdown = server.gui.add_dropdown("Exercise", ("a", "b"))
        assert viser_internals.gui_input_handle(server, None, dropdown._impl.uuid) is dropdown
        assert viser_internals.gui_input_handle(server, None, "no such control") is None
        buffered = server.gui._current_file_upload_states         # what forget_upload frees
        buffered["t"] = {"parts": [b"x" * 1000]}
        viser_internals.forget_upload(server, None, "t")
        assert "t" not in buffered
    finally:
        server.stop()
