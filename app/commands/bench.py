"""``python -m app bench``: closed-loop throughput of the ``kalman_noise`` loop.

Reports, from one run:
* the compiled loop's speed as a multiple of real time on one core, per wall
  second and per CPU second (the latter does not count time the machine gave
  to other processes);
* its speed against the same loop written in Python with filterpy's
  ``KalmanFilter.predict/update`` (same seed and noise), and the largest
  relative difference between the two loops' estimates;
* the aggregate speed of two simulations on two threads against one, and the
  CPU time per wall time of that run (near 2 when the loops run in parallel);
* the ``thrust_liftoff`` loop's speed (paper 003, target 100x real time);
* for every exercise, its simulation's speed and the share of one core a tab
  takes at the exercise's default time scale (for sizing a classroom server).
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np
from filterpy.kalman import KalmanFilter as FilterpyKalman

from lab_modules.exercises import get, registry
from lab_modules.loops import radial_axis_loop


def benchmark_simulation(use_estimate: bool = True, seed: int = 0):
    exercise = get("kalman_noise")
    values = exercise.resolve({"feedback": "estimated" if use_estimate else "measured", "seed": seed})
    return exercise.simulation(values)


def filterpy_loop(sim, n_steps: int) -> np.ndarray:
    """The loop of ``radial_axis_loop.run`` in plain Python with filterpy's filter.

    Uses a fresh ``sim``'s set-up and initial state and draws the same noise; returns
    the corrected position estimates [m]."""
    setup, kf_lab = sim.setup, sim.filter
    n = kf_lab.dim_x
    kf = FilterpyKalman(dim_x=n, dim_z=2, dim_u=1)
    kf.F, kf.B = kf_lab.A[:n, :n].copy(), kf_lab.B[:n].reshape(n, 1).copy()
    kf.H, kf.Q, kf.R = kf_lab.C[:, :n].copy(), kf_lab.Q[:n, :n].copy(), np.diag(kf_lab.R_diag)
    kf.x, kf.P = kf_lab.x.reshape(n, 1).copy(), kf_lab.covariance.copy()
    Ac, Bc, Cc, Dc = sim.controller_matrices
    ctrl, plant = sim.ctrl.copy(), sim.plant.copy()
    physics, sigma = sim.physics, setup.noise_sigma
    K_mx, K_mi, T = physics[9], physics[10], physics[8]
    reference, disturbance = sim.inputs(n_steps)
    noise = sim.noise(n_steps)
    A4, Bu4, Bf4 = sim.plant_linear
    scratch = [np.empty(4) for _ in range(5)]
    estimates = np.empty(n_steps)
    for k in range(n_steps):
        y = np.array([K_mx * plant[3] + sigma[2] * noise[k, 2], K_mi * plant[2] + sigma[3] * noise[k, 3]])
        kf.update(y.reshape(2, 1))
        estimates[k] = kf.x[0, 0]
        feedback = K_mx * kf.x[0, 0] if setup.use_estimate else y[0]
        e = K_mx * reference[k] - feedback
        u = float(np.clip(Cc[0] @ ctrl + Dc[0, 0] * e, -sim.u_limit_v, sim.u_limit_v))
        ctrl = Ac @ ctrl + Bc[:, 0] * e
        kf.predict(u=np.array([[u]]))
        if setup.nonlinear:
            radial_axis_loop.rk4_step(plant, u, disturbance[k], physics, T, *scratch)
        else:
            plant = A4 @ plant + Bu4 * u + Bf4 * disturbance[k]
        if setup.sensor_lag_s <= 0:
            plant[3] = plant[0]
        plant[1] += sigma[0] * noise[k, 0]
        plant[2] += sigma[1] * noise[k, 1]
    return estimates


def _throughput(seconds: float, threads: int, repeats: int = 7) -> tuple[float, float, float]:
    """Simulated seconds per wall second, summed over ``threads`` parallel
    simulations (best of ``repeats``), the process's CPU time per wall time in
    that run (about ``threads`` when the loops really run in parallel), and the
    simulated seconds per CPU second (best of ``repeats``: what one core buys,
    whatever else the machine runs)."""
    sims = [benchmark_simulation(seed=s) for s in range(threads)]
    for sim in sims:
        sim.advance(100)                                   # compile / warm up
    n_steps = int(seconds / sims[0].sample_time_s)
    best, per_cpu_second = (0.0, 0.0), 0.0
    for _ in range(repeats):
        workers = [threading.Thread(target=sim.advance, args=(n_steps,)) for sim in sims]
        cpu, start = time.process_time(), time.perf_counter()
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        best = max(best, (threads * seconds / wall, cpu / wall))
        per_cpu_second = max(per_cpu_second, threads * seconds / cpu)
    return (*best, per_cpu_second)


def thrust_liftoff_speed(seconds: float = 2.0, repeats: int = 5) -> dict:
    """The ``thrust_liftoff`` loop (paper 003: 0.1 ms samples, G(s), filter-PID, σ_v = 5 µm,
    relaunching every second as in the browser): simulated seconds per wall second and per
    CPU second on one thread, best of ``repeats``."""
    exercise = get("thrust_liftoff")
    values = exercise.resolve({"feedback": "estimated"})
    simulation = exercise.simulation(values)
    simulation.advance(100)                                  # compile / warm up
    n_steps = max(int(seconds / simulation.sample_time_s), 1)
    wall_speed = cpu_speed = 0.0
    for _ in range(repeats):
        cpu, start = time.process_time(), time.perf_counter()
        simulation.advance(n_steps)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        wall_speed = max(wall_speed, seconds / wall)
        cpu_speed = max(cpu_speed, seconds / cpu) if cpu > 0 else cpu_speed
    return {"realtime_factor_one_core": wall_speed, "realtime_factor_per_cpu_second": cpu_speed,
            "target_realtime_factor": 100}


def run(seconds: float = 2.0) -> dict:
    single, _, single_per_cpu_second = _throughput(seconds, 1)
    parallel, cpu_per_wall, _ = _throughput(seconds, 2)
    n_ref = 4000
    reference_sim, compiled_sim = benchmark_simulation(seed=7), benchmark_simulation(seed=7)
    start = time.perf_counter()
    reference = filterpy_loop(reference_sim, n_ref)
    filterpy_speed = n_ref * reference_sim.setup.rig.sample_time_s / (time.perf_counter() - start)
    compiled = compiled_sim.advance(n_ref)[:, 1 + radial_axis_loop.TRACE_COLUMNS.index("x_estimated_m")]
    scale = np.max(np.abs(reference))
    return {
        "exercise": "kalman_noise (nonlinear plant, estimated feedback, 4-state filter)",
        "realtime_factor_one_core": single,
        "realtime_factor_per_cpu_second": single_per_cpu_second,
        "realtime_factor_two_threads": parallel,
        "parallel_speedup_two_threads": parallel / single,
        "cpu_time_per_wall_time_two_threads": cpu_per_wall,
        "realtime_factor_filterpy_loop": filterpy_speed,
        "speedup_vs_filterpy_loop": single / filterpy_speed,
        "max_relative_estimate_difference_vs_filterpy": float(np.max(np.abs(compiled - reference)) / scale),
        "targets": {"realtime_factor_one_core": 200, "speedup_vs_filterpy_loop": 50},
        "thrust_liftoff": thrust_liftoff_speed(seconds),
    }


def classroom_load(seconds: float = 0.5) -> dict:
    """Per exercise: simulated seconds per wall second of its browser simulation
    (best of three), and the share of one core one tab needs at the default
    time scale (0.01 = a hundred tabs per core)."""
    load = {}
    for name, exercise in registry().items():
        values = exercise.resolve({})
        simulation = exercise.simulation(values)
        simulation.advance(10)                              # compile / warm up
        n_steps = max(int(seconds / simulation.sample_time_s), 1)
        speed = 0.0
        for _ in range(3):
            start = time.perf_counter()
            done = len(simulation.advance(n_steps))
            if done == 0:
                break
            speed = max(speed, done * simulation.sample_time_s / (time.perf_counter() - start))
        time_scale = values.get("time_scale", 1.0)
        load[name] = {"realtime_factor": speed, "default_time_scale": time_scale,
                      "core_share_per_tab": time_scale / speed if speed else float("nan")}
    return load


def main(seconds: float = 2.0, as_json: bool = False) -> int:
    result = run(seconds)
    result["classroom_load"] = classroom_load()
    if as_json:
        print(json.dumps(result, indent=2))
    else:
        for name, value in result.items():
            print(f"{name}: {value}")
    return 0
