"""One planning job: check the request, run the information-gathering planner (or the
paper's random baseline) with progress reports, and say how far a failed search got.

`run_plan` is what ``mavsysid plan`` and the demo call; tests call it directly.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from mavsysid.planner.plan_request import check_request
from mavsysid.planner.results import PlannerSettings, PlanProgress, PlanResult
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from mavsysid.errors import JobFailedError

__all__ = ["ProgressCallback", "progress_bar", "run_plan"]

#: Called with each progress report of a planning run.
ProgressCallback = Callable[[PlanProgress], None]


@contextmanager
def progress_bar(settings: PlannerSettings) -> Iterator[ProgressCallback]:
    """A tqdm bar on stderr fed by the planner's progress reports (off when not a tty)."""
    from tqdm import tqdm  # only the console script needs it

    by_samples = settings.max_samples is not None
    total = settings.max_samples if by_samples else settings.planning_time
    # disable=None: tqdm stays quiet when stderr is not a terminal (logs, pipes, CI).
    with tqdm(total=total, unit="sample" if by_samples else "s", file=sys.stderr,
              disable=None, leave=False, dynamic_ncols=True,
              bar_format=None if by_samples else "{l_bar}{bar}| {n:.0f}/{total:.0f} s{postfix}",
              ) as bar:

        def report(progress: PlanProgress) -> None:
            done = progress.samples if by_samples else min(progress.elapsed, float(total))
            bar.update(done - bar.n)
            best = "—" if progress.best_dopt is None else f"{progress.best_dopt:.3g}"
            # A dict keeps this order; keyword arguments would be sorted by name.
            bar.set_postfix({"vertices": progress.vertices, "beliefs": progress.beliefs,
                             "D-opt": best, "elapsed": f"{progress.elapsed:.1f} s"},
                            refresh=False)

        yield report


def run_plan(
    vehicle: str | Path | VehicleConfig, settings: PlannerSettings, random: bool = False,
    progress: bool | ProgressCallback = True,
) -> PlanResult:
    """Check a planning request and plan.

    Parameters
    ----------
    vehicle : str, Path or VehicleConfig
        Shipped vehicle name, TOML path, or a loaded configuration.
    settings : PlannerSettings
        Budget, planning time and/or sample count, box, start, seed.
    random : bool
        Use the paper's random baseline instead of the information-gathering planner.
    progress : bool or callable
        True: a progress bar on stderr (when it is a terminal); False: none; a callable:
        called with each `PlanProgress`.

    Raises
    ------
    InputError
        See `mavsysid.planner.plan_request.check_request`, and unknown or malformed
        vehicles.
    JobFailedError
        No feasible trajectory was found; the message says how long was searched and how
        large the graph grew.
    """
    config = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
    # Checked here as well as by the planner, so that a refused request loads no planner.
    check_request(config, settings)
    if random:
        from mavsysid.planner.baseline import plan_random as planner
    else:
        from mavsysid.planner.rrbt import plan as planner
    last: list[PlanProgress] = []

    def track(report: ProgressCallback | None) -> ProgressCallback:
        def callback(p: PlanProgress) -> None:
            last[:] = [p]
            if report is not None:
                report(p)
        return callback

    try:
        if progress is True:
            with progress_bar(settings) as bar:
                return planner(config, settings, progress=track(bar))
        return planner(config, settings, progress=track(progress or None))
    except JobFailedError as error:
        text = str(error)
        if text.startswith("no feasible") or not last:
            raise
        p = last[0]
        raise JobFailedError(f"no feasible trajectory found in {p.elapsed:.1f} s "
                             f"({p.vertices} vertices, {p.edges} edges): {text}") from None
