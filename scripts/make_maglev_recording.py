"""Record a lead-lag controlled run of the maglev ball to CSV (paper 004 §3.5, Fig. 3.25).

Without options it rewrites the recording shipped with the lab,
static/recordings/maglev_leadlag.csv: the Table 3.1 plant, 1 s with the ball
resting on the positioning tool, then 5 s levitated at 14.8 mm, sensor noise
0.0034 mm (Table 3.2), seed 2005.

    python scripts/make_maglev_recording.py [--out FILE] [--noise-mm S] [--duration S] [--seed N]
"""

import argparse
from pathlib import Path

from lab_modules import recordings
from lab_modules.loops.maglev_loop import record_lead_lag_run

SHIPPED = Path(__file__).resolve().parent.parent / "static" / "recordings" / "maglev_leadlag.csv"
SHIPPED_SETTINGS = {"duration_s": 6.0, "still_s": 1.0, "sensor_noise_m": 3.4e-6, "seed": 2005}

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SHIPPED, help="CSV file to write")
    parser.add_argument("--noise-mm", type=float, default=SHIPPED_SETTINGS["sensor_noise_m"] * 1e3,
                        help="position sensor noise sigma [mm]")
    parser.add_argument("--duration", type=float, default=SHIPPED_SETTINGS["duration_s"],
                        help="recorded seconds (the first second is the still segment)")
    parser.add_argument("--seed", type=int, default=SHIPPED_SETTINGS["seed"], help="random seed")
    args = parser.parse_args()
    run = record_lead_lag_run(duration_s=args.duration, still_s=SHIPPED_SETTINGS["still_s"],
                              sensor_noise_m=args.noise_mm * 1e-3, seed=args.seed)
    recordings.write(args.out, run)
    print(f"wrote {args.out}")
