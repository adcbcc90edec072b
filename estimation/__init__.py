"""θ with honest uncertainties from a recorded flight: the public face of estimation.

`estimate` answers θ per parameter from a flight read by `load_flight`: the force and
torque balance (`mavsysid.estimation.balance`) checked by the paper's parameter EKF and its
batch refinement (`mavsysid.estimation.filter`, `mavsysid.estimation.batch`). The other
names here are what the rest of mavsysid builds on: the flight and result types, the
equation-error view of a flight (smoothed pose, the model's accelerations through the same
smoother) that ``diagnose`` extends, the plausibility checks, and the reports. The report
writers load matplotlib and rerun, so they are imported when first used.

Subpackages and modules, by topic: ``readers`` (logs → `FlightData`), ``flight`` (the
flight and its slow inputs), ``signals`` (uniform grids, smoothing, derivatives, pose
noise), ``balance`` (the force and torque balance), ``filter`` (the EKF, its guard and
maximum-likelihood fits), ``batch`` (the MAP refinement), ``robust`` (the HAC covariance),
``checks`` (refusals), ``answer`` (the per-parameter answer), ``results``, ``report``,
``progress``.
"""

from __future__ import annotations

import importlib
from typing import Any

from mavsysid.estimation.answer import FilterEstimator, check_result, estimate
from mavsysid.estimation.balance.fit import (
    WrenchBalanceSettings,
    compare_wrench,
    fit_wrench_balance,
)
from mavsysid.estimation.balance.rows import consistent_accelerations, model_accelerations
from mavsysid.estimation.checks import (
    check_kinematics,
    check_plausible,
    implausibility,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    estimate_parameters,
    estimate_with_effects,
)
from mavsysid.estimation.filter.guard import NIS_FACTOR, nis_level
from mavsysid.estimation.flight import MIN_DURATION, FlightData
from mavsysid.estimation.progress import (
    StageLog,
    progress_wanted,
    report_progress,
    report_stage,
    stage_listener,
)
from mavsysid.estimation.readers import READERS, describe_log_kinds, load_flight
from mavsysid.estimation.report.text import (
    format_table,
    noise_from_flights,
    read_noise_met,
    read_set_aside,
    result_to_json,
    updated_vehicle,
    write_estimate_json,
    write_history_csv,
)
from mavsysid.estimation.results import (
    AT_BOUND,
    AXIS_NAMES,
    AXIS_UNITS,
    CONVERGENCE_TOLERANCE,
    DETERMINED,
    NOT_DETERMINED,
    EstimationHistory,
    EstimationResult,
    FittedEffect,
    NoiseMet,
    ParameterEstimate,
    WrenchBalanceResult,
    convergence_time,
    prior_from_config,
)
from mavsysid.estimation.signals import (
    MAX_JITTER,
    SmoothedPose,
    SmootherSettings,
    acceleration_kernel,
    noise_gain,
    smooth_pose,
    uniform_step,
)

#: Public names whose modules load matplotlib or rerun: imported on first use.
_LAZY = {
    **{name: "mavsysid.estimation.report.figures" for name in (
        "ReportTable", "flight_lines", "html_page", "plot_rotor_speeds",
        "plot_wrench", "save_figure", "write_estimate_report", "write_index")},
    **{name: "mavsysid.estimation.report.recording" for name in (
        "ROTOR_COLORS", "log_estimation", "write_estimation_rrd")},
}

__all__ = [
    "AT_BOUND", "AXIS_NAMES", "AXIS_UNITS", "CONVERGENCE_TOLERANCE", "DETERMINED", "MAX_JITTER",
    "MIN_DURATION", "NIS_FACTOR", "NOT_DETERMINED", "READERS", "EstimationHistory",
    "EstimationResult", "EstimatorSettings", "FilterEstimator", "FittedEffect", "FlightData",
    "NoiseMet", "ParameterEKF", "ParameterEstimate", "SmoothedPose", "SmootherSettings", "StageLog",
    "WrenchBalanceResult", "WrenchBalanceSettings", "acceleration_kernel", "check_kinematics",
    "check_plausible", "check_result", "compare_wrench", "consistent_accelerations",
    "convergence_time",
    "describe_log_kinds", "estimate", "estimate_parameters", "estimate_with_effects",
    "fit_wrench_balance", "format_table", "implausibility", "load_flight",
    "model_accelerations", "nis_level", "noise_from_flights", "noise_gain", "prior_from_config",
    "progress_wanted",
    "read_noise_met", "read_set_aside", "report_progress", "report_stage", "result_to_json",
    "smooth_pose", "stage_listener",
    "uniform_step", "updated_vehicle", "vanishing_floor", "vanishing_parameters",
    "write_estimate_json", "write_history_csv", *_LAZY,
]


def __getattr__(name: str) -> Any:
    """A report writer's name, imported from its module on first use."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
