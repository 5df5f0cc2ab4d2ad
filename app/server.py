"""The lab's web server: one viser server, one ``LabSession`` per browser tab."""

from __future__ import annotations

import threading
import time

import viser

from app.session import LabSession
from lab_modules.exercises import get


def serve(host: str = "127.0.0.1", port: int = 8080, exercise: str = "kalman_noise") -> None:
    """Serve the lab until interrupted; every connecting tab gets its own simulation,
    starting on ``exercise`` (each tab can switch)."""
    chosen = get(exercise)
    chosen.simulation(chosen.resolve({})).advance(1)       # compile the loop before the first tab
    server = viser.ViserServer(host=host, port=port, label="AMB estimation lab", verbose=False)
    sessions: dict[int, LabSession] = {}
    lock = threading.Lock()

    @server.on_client_connect
    def _(client: viser.ClientHandle) -> None:
        session = LabSession(client, chosen)
        with lock:
            sessions[client.client_id] = session

    @server.on_client_disconnect
    def _(client: viser.ClientHandle) -> None:
        with lock:
            session = sessions.pop(client.client_id, None)
        if session is not None:
            session.close()

    print(f"AMB estimation lab: open http://{host}:{port} in a browser (Ctrl+C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        server.stop()
