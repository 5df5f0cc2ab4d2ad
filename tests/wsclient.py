"""A raw websocket client of the lab (no browser): speaks viser's protocol enough
to find the GUI, move a control and watch the server's updates.

Client -> server: one msgpack map per message, ``{"type": "GuiUpdateMessage",
"uuid": ..., "updates": {"value": ...}}``.  Server -> client: batches framed as
[8 bytes msgpack size][8 bytes compressed size][zstd msgpack {"messages": [...]}]
[binary buffers] (``viser.infra._infra._message_producer``).
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import threading
import time
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import msgspec
import viser
import websockets
import zstandard

REPO = Path(__file__).resolve().parents[1]
CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [0.3, 0.3, 0.3], "fov": 1.0,
          "near": 0.01, "far": 100.0, "image_height": 768, "image_width": 386, "look_at": [0.0, 0.0, 0.0],
          "up_direction": [0.0, 0.0, 1.0]}


def local_storage_answer(request: dict, value: str | None = None) -> dict:
    """What a browser answers to the lab's request for a localStorage value."""
    return {"type": "LocalStorageGetItemResponseMessage", "value": value, "error": None,
            "request_uuid": request["request_uuid"]}


class RawTab:
    """One tab over a raw websocket."""

    def __init__(self, keep_messages: bool = False):
        """``keep_messages``: keep every message the server sent, in ``messages`` (short tests only)."""
        self.elements: dict[str, dict] = {}      # uuid -> {"type", "label", "props", "content"}
        self.messages: list[dict] | None = [] if keep_messages else None
        self.updates: list[tuple[float, str, dict]] = []   # (perf_counter, uuid, updates)
        self.websocket = None
        self.reader: asyncio.Task | None = None
        self.closed = asyncio.Event()
        self.close_code: int | None = None
        self._decompressor = zstandard.ZstdDecompressor()

    async def connect(self, url: str, origin: str | None = None) -> RawTab:
        headers = {"Origin": origin} if origin else None
        self.websocket = await websockets.connect(
            url.replace("http://", "ws://"), subprotocols=[f"viser-v{viser.__version__}"],
            additional_headers=headers, max_size=None, open_timeout=30)
        self.reader = asyncio.create_task(self._read())
        await self.send(CAMERA)                  # viser builds a tab after its first camera message
        return self

    async def _read(self) -> None:
        try:
            async for frame in self.websocket:
                size = int.from_bytes(frame[:8], "little")
                compressed = int.from_bytes(frame[8:16], "little")
                batch = msgspec.msgpack.decode(self._decompressor.decompress(frame[16:16 + compressed],
                                                                            max_output_size=size))
                now = time.perf_counter()
                for message in batch["messages"]:
                    self._take(now, message)
        except websockets.ConnectionClosed:
            pass
        finally:
            self.close_code = self.websocket.close_code
            self.closed.set()

    def _take(self, now: float, message: dict) -> None:
        kind = message.get("type", "")
        uuid = message.get("uuid")
        if self.messages is not None:
            self.messages.append(message)
        if kind == "LocalStorageGetItemRequestMessage":   # answered like a browser with nothing stored
            asyncio.get_running_loop().create_task(self.send(local_storage_answer(message)))
        if kind == "GuiUpdateMessage":
            self.updates.append((now, uuid, message["updates"]))
            element = self.elements.get(uuid)
            for prop in ("content", "_markdown"):              # markdown text travels as "_markdown"
                if element is not None and prop in message["updates"]:
                    element["content"] = message["updates"][prop]
        elif kind == "GuiRemoveMessage":
            self.elements.pop(uuid, None)
        elif kind.startswith("Gui") and isinstance(uuid, str) and isinstance(message.get("props"), dict):
            props = message["props"]
            self.elements[uuid] = {"type": kind, "label": props.get("label") or props.get("title"), "props": props,
                                   "content": props.get("_markdown", props.get("content")), "value": message.get("value")}

    def find(self, kind: str, label: str | None = None, content: str | None = None) -> str | None:
        for uuid, element in self.elements.items():
            if element["type"] != kind:
                continue
            if label is not None and element["label"] != label:
                continue
            if content is not None and (element["content"] or "") != content:
                continue
            return uuid
        return None

    def find_containing(self, kind: str, text: str) -> str | None:
        for uuid, element in self.elements.items():
            if element["type"] == kind and text in (element["content"] or ""):
                return uuid
        return None

    async def wait_for(self, predicate, timeout: float = 60.0):
        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            result = predicate()
            if result:
                return result
            if self.closed.is_set():
                return predicate()
            await asyncio.sleep(0.02)
        return predicate()

    async def send(self, message: dict) -> None:
        await self.websocket.send(msgspec.msgpack.encode(message))

    async def set_value(self, uuid: str, value) -> None:
        await self.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": {"value": value}})

    def update_times(self, uuid: str, prop: str, since: float = 0.0) -> list[float]:
        return [t for t, u, updates in self.updates if u == uuid and prop in updates and t >= since]

    async def close(self) -> None:
        if self.websocket is not None:
            await self.websocket.close()
        if self.reader is not None:
            await asyncio.wait([self.reader], timeout=5)


@contextmanager
def lab_process(port: int, *args: str, data_dir: Path | None = None, log: Path | None = None,
                timeout_s: float = 120.0):
    """``python -m app --port PORT ARGS`` as a child process; yields the Popen once it answers HTTP."""
    command = [sys.executable, "-m", "app", "--port", str(port), *args]
    if data_dir is not None:
        command += ["--data-dir", str(data_dir)]
    out = open(log, "w") if log else subprocess.DEVNULL   # noqa: SIM115 - closed below
    server = subprocess.Popen(command, cwd=REPO, stdout=out, stderr=subprocess.STDOUT, text=True,
                              env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    try:
        deadline = time.time() + timeout_s
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}", timeout=5).close()
                break
            except OSError:
                if server.poll() is not None or time.time() > deadline:
                    raise RuntimeError(f"the lab did not start: {log.read_text() if log else ''}") from None
                time.sleep(0.3)
        yield server
    finally:
        if server.poll() is None:
            server.terminate()
            try:
                server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                server.kill()
        if log:
            out.close()


def process_threads(pid: int) -> int:
    return len(list(Path(f"/proc/{pid}/task").iterdir()))


def process_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    import os
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def masked_frame(payload: bytes) -> bytes:
    """One binary websocket frame as a client sends it, masked with the key 0 (legal, and
    the payload stays as it is): lets a flood bypass the client library's per-message cost."""
    if len(payload) < 126:
        head = bytes((0x82, 0x80 | len(payload)))
    else:
        head = bytes((0x82, 0x80 | 126)) + len(payload).to_bytes(2, "big")
    return head + b"\0\0\0\0" + payload


async def flood(url: str, seconds: float, label: str = "Position sensor noise σ [µm]") -> int:
    """Send slider updates as fast as the server takes them for ``seconds``; returns how many were sent."""
    tab = await RawTab().connect(url)
    slider = await tab.wait_for(lambda: tab.find("GuiSliderMessage", label), 120)
    batch = b"".join(masked_frame(msgspec.msgpack.encode(
        {"type": "GuiUpdateMessage", "uuid": slider, "updates": {"value": 1.0 + (i % 100) / 100}}))
        for i in range(100))
    transport = tab.websocket.transport
    print("flooding", flush=True)
    sent, end = 0, time.perf_counter() + seconds
    while time.perf_counter() < end:
        if transport.get_write_buffer_size() > 1_000_000:   # the server reads slower: wait for it
            await asyncio.sleep(0.005)
            continue
        transport.write(batch)
        sent += 100
        await asyncio.sleep(0)
    await tab.close()
    return sent


if __name__ == "__main__":
    # python -m tests.wsclient flood URL SECONDS: prints "flooding" when it starts, then the number sent
    if sys.argv[1] == "flood":
        print(asyncio.run(flood(sys.argv[2], float(sys.argv[3]))), flush=True)


def run_async(coroutine):
    """``asyncio.run(coroutine)`` on a thread of its own: the browser tests' synchronous
    Playwright keeps an event loop running on the main thread, where asyncio.run refuses to start."""
    outcome = {}

    def target():
        try:
            outcome["value"] = asyncio.run(coroutine)
        except BaseException as error:  # noqa: BLE001 - re-raised in the caller
            outcome["error"] = error

    thread = threading.Thread(target=target)
    thread.start()
    thread.join()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]


#: the readouts table's header: a tab that shows it has built its lab
READOUTS = "| quantity | value | unit |"


def url(port: int) -> str:
    return f"http://127.0.0.1:{port}"


async def lab_tab(port: int, timeout: float = 120.0) -> RawTab:
    """A raw tab on the lab at ``port``, once its readouts table is there."""
    tab = await RawTab().connect(url(port))
    assert await tab.wait_for(lambda: tab.find_containing("GuiMarkdownMessage", READOUTS), timeout)
    return tab
