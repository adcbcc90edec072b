"""Running the estimator on one fuzzed log and classifying what it did.

`estimate_outcome` calls the library entry point the CLI calls
(`mavsysid.pipeline.estimate.run_estimate`) and sorts the result into exit 0 (with
the largest relative error of θ against the truth, and the largest distance of the truth
in σ over the determined parameters), a documented refusal (the exception type that maps
to exit 2 or 3), or a traceback (any other exception: exit 1, a bug). `fuzz_plan` draws
the seeded mix of (format, value mutation, byte mutation) cases, the IMU's mutations
among the value mutations; `imu_plan` gives every IMU value mutation in every format in
turn.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mavsysid.estimation.results import DETERMINED
from mavsysid.pipeline.estimate import run_estimate

from mavsysid.errors import MavsysidError
from tests.support.log_fuzz import BYTE_MUTATIONS, FORMATS, IMU_MUTATIONS, VALUE_MUTATIONS

__all__ = ["Outcome", "estimate_outcome", "fuzz_plan", "imu_plan"]


@dataclass(frozen=True)
class Outcome:
    """What the estimator did with one log.

    Attributes
    ----------
    kind : str
        ``"exit0"``, the refusing error type's name (``"LogFormatError"`` …), or
        ``"traceback"``.
    error : float
        Exit 0: max over θ of |θ̂ − θ| / |θ|; else NaN.
    sigma_error : float
        Exit 0: max over the parameters of θ the estimate calls determined of |θ̂ − θ| / σ
        (0 when none is); else NaN.
    seconds : float
        Wall time of the call, s.
    message : str
        The refusal's message, or the traceback's last line.
    """

    kind: str
    error: float
    seconds: float
    message: str
    sigma_error: float = np.nan


def estimate_outcome(path: Path, vehicle: str, theta: np.ndarray) -> Outcome:
    """Estimate θ from ``path`` with the shipped ``vehicle``; classify the result."""
    start = time.perf_counter()
    try:
        run = run_estimate(path, vehicle)
    except MavsysidError as exc:
        return Outcome(type(exc).__name__, np.nan, time.perf_counter() - start, str(exc))
    except Exception:  # a bug: what the CLI reports as an internal error (exit 1)
        last = traceback.format_exc().strip().splitlines()[-1]
        return Outcome("traceback", np.nan, time.perf_counter() - start,
                       f"{last} | {traceback.format_exc()}")
    final, six = run.result.final, len(theta)  # θ first, nuisance quantities after
    off = np.abs(final.value[:six] - theta)
    error = float(np.max(off / np.abs(theta)))
    determined = np.array([s == DETERMINED for s in run.result.status[:six]]
                          if run.result.status else np.ones(six, dtype=bool))
    with np.errstate(divide="ignore", invalid="ignore"):
        in_sigma = off / final.sigma[:six]
    in_sigma[~np.isfinite(in_sigma)] = np.inf  # no σ, or none to speak of, is no interval
    sigma_error = float(np.max(in_sigma[determined], initial=0.0))
    return Outcome("exit0", error, time.perf_counter() - start, "", sigma_error)


def fuzz_plan(count: int, seed: int) -> list[tuple[str, str, str, int]]:
    """``count`` seeded cases (format suffix, value mutation, byte mutation, case seed).

    Half the cases mutate values only (the log stays well-formed, the hard part for the
    estimator), a quarter bytes only, a quarter both; CSV-only byte mutations (``words``)
    go to CSV logs.
    """
    rng = np.random.default_rng(seed)
    values = [m for m in VALUE_MUTATIONS if m != "none"]
    plan = []
    for i in range(count):
        suffix = FORMATS[i % len(FORMATS)]
        byte_choices = [b for b in BYTE_MUTATIONS if b != "none"
                        and (b != "words" or suffix == ".csv")]
        r = rng.random()
        value = str(rng.choice(values)) if r < 0.75 else "none"
        byte = "none" if r < 0.5 else str(rng.choice(byte_choices))
        plan.append((suffix, value, byte, int(rng.integers(0, 2**31))))
    return plan


def imu_plan(count: int, seed: int) -> list[tuple[str, str, str, int]]:
    """``count`` seeded cases of the IMU's value mutations alone (byte mutation
    ``"none"``): every (format, IMU mutation) pair in turn, the pairs' order shuffled
    once, so that ``count`` ≥ k × pairs covers each pair k times."""
    rng = np.random.default_rng(seed)
    pairs = [(suffix, m) for m in IMU_MUTATIONS for suffix in FORMATS]
    order = rng.permutation(len(pairs))
    return [(*pairs[order[i % len(pairs)]], "none", int(rng.integers(0, 2**31)))
            for i in range(count)]
