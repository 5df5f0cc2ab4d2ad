"""The lab's web server: one viser server, one ``LabSession`` per browser tab."""

from __future__ import annotations

import threading
import time

import viser

from app.session import LabSession
from lab_modules.exercises import get
from lab_modules.scenes.bearing import CAMERA_POSITION


def serve(host: str = "127.0.0.1", port: int = 8080, exercise: str = "kalman_noise") -> None:
    """Serve the lab until interrupted; every connecting tab gets its own simulation,
    starting on ``exercise`` (each tab can switch)."""
    chosen = get(exercise)
    chosen.simulation(chosen.resolve({})).advance(1)       # compile the loop before the first tab
    server = viser.ViserServer(host=host, port=port, label="AMB estimation lab", verbose=False)
    # The default view direction (the space diagonal), from farther away: the 3D view is the
    # narrow gap between the docked controls and charts, and the scenes must fit its width.
    server.initial_camera.position = tuple(CAMERA_POSITION)
    server.initial_camera.look_at = (0.0, 0.0, 0.0)
    sessions: dict[int, LabSession] = {}
    lock = threading.Lock()

    @server.on_client_connect
    def _(client: viser.ClientHandle) -> None:
        session = LabSession(client, chosen)
        with lock:
            sessions[client.client_id] = session

    @server.on_client_disconnect
    async def _(client: viser.ClientHandle) -> None:
        # async: runs on the event loop right after the connection closes (a plain function would
        # wait for the thread pool while the tab's threads keep writing to the dead connection)
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
