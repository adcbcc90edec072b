"""How a small vehicle's logger writes the pose: jittered timestamps and dropped samples.

The simulator logs at exact multiples of the log period. A real on-board logger stamps
each sample with some jitter, quantises the stamp to its clock, and loses samples: single
ones now and then, and bursts (a radio or SD-card hiccup). `degrade_pose_log` rewrites a
simulated flight's ``pose.csv`` that way (``truth.csv`` keeps the exact times) and records
what it did under ``meta.json`` ``log_timing``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from mavsysid.formats.flight_dir import read_meta, write_meta

__all__ = ["LogTiming", "degrade_pose_log"]


@dataclass(frozen=True)
class LogTiming:
    """Timestamp jitter and sample loss of a logger.

    Attributes
    ----------
    jitter : float
        s, σ of the Gaussian stamp error, clipped to ±0.4 of the log period so that the
        stamps stay in order.
    resolution : float
        s, stamps are rounded to this clock tick (0: not rounded). A tick of the order of
        the period can make two stamps equal, as real logs do.
    drop_probability : float
        Fraction of single samples lost independently.
    gaps : int
        Number of burst losses.
    gap_duration : tuple of 2 float
        s, the range a burst's length is drawn from (uniformly).
    seed : int
    """

    jitter: float = 2e-4
    resolution: float = 0.0
    drop_probability: float = 0.02
    gaps: int = 3
    gap_duration: tuple[float, float] = (0.02, 0.15)
    seed: int = 0

    def kept_rows(self, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Boolean mask (N,) of the samples at times ``t`` (s) that the logger keeps.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Sample times, s.
        rng : numpy.random.Generator
            Seeded source of the losses.
        """
        keep = rng.random(t.size) >= self.drop_probability
        keep[[0, -1]] = True
        span = t[-1] - t[0]
        for _ in range(self.gaps):
            length = rng.uniform(*self.gap_duration)
            # Bursts away from the ends, so the log still starts and stops at its bounds.
            start = t[0] + rng.uniform(0.1, 0.9) * max(span - length, 0.0)
            keep &= ~((t >= start) & (t < start + length))
        return keep

    def stamps(self, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The logged stamps (N,) of samples taken at times ``t`` (s, uniform).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Sample times, s.
        rng : numpy.random.Generator
            Seeded source of the jitter.
        """
        period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        error = np.clip(rng.normal(0.0, self.jitter, t.size), -0.4 * period, 0.4 * period)
        stamped = t + error
        if self.resolution > 0.0:
            stamped = np.round(stamped / self.resolution) * self.resolution
        return stamped


def degrade_pose_log(directory: str | Path, timing: LogTiming) -> int:
    """Rewrite ``directory``/pose.csv with ``timing``'s jitter and losses; rows kept.

    The sample's values stay those of its true time; only its stamp moves. Rows whose
    rounded stamps coincide are all kept (the reader decides what to do with them).

    Parameters
    ----------
    directory : str or Path
        A flight directory with ``pose.csv``.
    timing : LogTiming
        Jitter, losses and gaps to apply.
    """
    directory = Path(directory)
    path = directory / "pose.csv"
    frame = pd.read_csv(path)
    rng = np.random.default_rng(timing.seed)
    t = frame["t"].to_numpy(dtype=float)
    keep = timing.kept_rows(t, rng)
    frame["t"] = timing.stamps(t, rng)
    frame = frame[keep]
    frame.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")
    meta = read_meta(directory / "meta.json")
    meta["log_timing"] = {**asdict(timing), "rows_kept": int(keep.sum()),
                          "rows_simulated": int(t.size)}
    write_meta(directory / "meta.json", meta)
    return int(keep.sum())
