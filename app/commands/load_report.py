"""The figures of one load-bench step (``app.commands.load_bench``) and how the bench prints
them: scope updates per second (minimum and median over the tabs), bytes per second, the
server's CPU per tab and per update, slider-to-readout latency (median, p95, max) and every tab
that stalled, with the reason."""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

import numpy as np

MIN_UPDATES_PER_S = 20.0        # a step passes when every tab gets this many scope updates per second


@dataclass
class Step:
    clients: int
    updates_min: float
    updates_median: float
    kbytes_per_s_median: float
    kbytes_per_s_max: float
    server_cores: float           # CPU seconds per wall second of all server processes
    client_cores: float           # the same for this benchmark's own process (the tabs)
    connected: int
    updates: int                  # scope updates received by all tabs in the window
    window_s: float
    readout_latencies_s: list[float] = field(default_factory=list)   # slider move -> new readout, all tabs
    stalls: list[dict] = field(default_factory=list)   # tab (1 = the first connected), worker, why (Tab.stall)
    on_scope: int | None = None   # tabs showing the Scope, whose updates are counted (None: all)

    @property
    def ok(self) -> bool:
        return self.connected == self.clients and self.updates_min >= MIN_UPDATES_PER_S and not self.stalls

    def row(self) -> dict:
        return {"clients": self.clients, "tabs_on_scope": self.clients if self.on_scope is None else self.on_scope,
                "updates_per_s_min": round(self.updates_min, 1),
                "updates_per_s_median": round(self.updates_median, 1),
                "kB_per_s_median": round(self.kbytes_per_s_median, 1),
                "kB_per_s_max": round(self.kbytes_per_s_max, 1),
                "server_cores": round(self.server_cores, 3),
                "server_core_percent_per_tab": round(100 * self.server_cores / self.clients, 2),
                "server_cpu_ms_per_update": round(1e3 * self.server_cores * self.window_s / max(self.updates, 1), 3),
                "server_core_percent_per_tab_at_25_per_s": round(
                    100 * 25 * self.server_cores * self.window_s / max(self.updates, 1), 2),
                "bench_client_cores": round(self.client_cores, 3),
                "slider_moves_answered": len(self.readout_latencies_s),
                "readout_latency_s_median": _rounded(statistics.median(self.readout_latencies_s)
                                                     if self.readout_latencies_s else None),
                "readout_latency_s_p95": _rounded(float(np.percentile(self.readout_latencies_s, 95))
                                                  if self.readout_latencies_s else None),
                "readout_latency_s_max": _rounded(max(self.readout_latencies_s, default=None)),
                "stalled_tabs": len(self.stalls), "stalls": self.stalls,
                "connected": self.connected, "ok": self.ok}


def _rounded(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds, 3)


def print_step(step: Step) -> None:
    """One line per step, then one per stalled tab."""
    r = step.row()
    print(f"  {r['clients']:4d} tabs: scope updates/s min {r['updates_per_s_min']:5.1f} "
          f"median {r['updates_per_s_median']:5.1f}"
          + (f" (the {r['tabs_on_scope']} tabs on the Scope)" if r["tabs_on_scope"] != r["clients"] else "")
          + f"; {r['kB_per_s_median']:6.1f} kB/s per tab; "
          f"server {r['server_cores']:.2f} cores = {r['server_core_percent_per_tab']:.2f} % of a core "
          f"per tab ({r['server_cpu_ms_per_update']:.2f} ms per update = "
          f"{r['server_core_percent_per_tab_at_25_per_s']:.2f} % at 25/s); bench clients {r['bench_client_cores']:.2f} cores"
          + (f"; slider move to readout: median {r['readout_latency_s_median']:.2f} s, "
             f"p95 {r['readout_latency_s_p95']:.2f} s, max {r['readout_latency_s_max']:.2f} s "
             f"({r['slider_moves_answered']} moves)"
             if r["slider_moves_answered"] else "")
          + f"; stalled tabs: {r['stalled_tabs']}"
          + ("" if step.ok else "  <- below target"), flush=True)
    for stall in r["stalls"]:
        print(f"         tab {stall['tab']} ({stall['worker'] or 'one process'}) stalled: {stall['why']}", flush=True)


def print_summary(result: dict) -> None:
    """The capacity and, with ``--breakdown``, the bytes per tab by message kind."""
    print(f"largest step with every tab >= {MIN_UPDATES_PER_S:.0f} scope updates/s and none stalled: "
          f"{result['largest_clients_at_min_updates']} tabs")
    if "bytes_by_kind_per_tab_run" in result:
        print("bytes per tab by message kind (" + result["breakdown_note"] + "):")
        for kind, value in result["bytes_by_kind_per_tab_run"].items():
            print(f"  {kind:<45} {value / 1e3:9.1f} kB")
