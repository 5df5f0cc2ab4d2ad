"""Write the maglev recording shipped with the lab (static/recordings/maglev_leadlag.csv).

A lead-lag controlled run of the paper 004 plant (Table 3.1): 1 s with the
ball resting on the positioning tool, then 5 s levitated at 14.8 mm, sensor
noise 0.0034 mm (Table 3.2), seed 2005.  Usage: python scripts/make_maglev_recording.py
"""

from pathlib import Path

from lab_modules import recordings
from lab_modules.maglev_simulation import record_lead_lag_run

SHIPPED = Path(__file__).resolve().parent.parent / "static" / "recordings" / "maglev_leadlag.csv"
SHIPPED_SETTINGS = {"duration_s": 6.0, "still_s": 1.0, "sensor_noise_m": 3.4e-6, "seed": 2005}

if __name__ == "__main__":
    recordings.write(SHIPPED, record_lead_lag_run(**SHIPPED_SETTINGS))
    print(f"wrote {SHIPPED}")
