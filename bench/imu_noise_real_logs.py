"""IMU noise and bias in the real PX4 logs of ``../shared/real-logs``: the basis of the
``[noise]`` IMU defaults (`mavsysid.vehicle.config_types`, docs/architecture.md "Noise
defaults").

For each ``.ulg``: the IMU `mavsysid.formats.ulog.read_ulog` reads, its rate, the white
noise (σ per axis of the samples minus their 15 Hz low-pass, a 2-pole Butterworth run
forwards and backwards) over the first 2 s (at rest) and the middle third of the log, and
the constant part at rest (the mean gyro over the first 2 s, and |mean specific force|
minus 9.81 m/s²).

    python bench/imu_noise_real_logs.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

REAL = REPO.parent / "shared" / "real-logs"


def main() -> None:
    from mavsysid.formats.ulog import read_ulog
    from mavsysid.vehicle.config import load_vehicle

    vehicle = load_vehicle("sitl_quad")
    for path in sorted(REAL.glob("*.ulg")):
        log = read_ulog(path, vehicle)
        print(path.name)
        for name in ("gyro", "accel"):
            series = getattr(log, name)
            rate = 1.0 / float(np.median(np.diff(series.t)))
            b, a = butter(2, 15.0 / (rate / 2.0))
            white = series.values - filtfilt(b, a, series.values, axis=0)
            n = series.t.size
            rest, middle = slice(0, int(2 * rate)), slice(n // 3, 2 * n // 3)
            mean = series.values[rest].mean(axis=0)
            constant = (f"mean {np.abs(mean).round(4)} rad/s" if name == "gyro" else
                        f"|mean| − 9.81 = {np.linalg.norm(mean) - 9.81:+.3f} m/s²")
            print(f"  {name:5s} {series.label:35s} {rate:6.1f} Hz  white σ rest "
                  f"{white[rest].std(axis=0).round(4)}, middle "
                  f"{white[middle].std(axis=0).round(4)}; at rest {constant}")


if __name__ == "__main__":
    main()
