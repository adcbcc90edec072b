"""Every public function and method documents each of its parameters (numpydoc).

Public means: named in the ``__all__`` of a module of the installed package and defined in
that module (a re-export is checked where it is defined). For a function, a numba kernel
(its Python function) and every public method a public class defines, each parameter but
``self``/``cls`` must have an entry in a "Parameters" (or "Other Parameters") section of its
docstring, the way python-control's ``tests/docstrings_test.py`` checks. A class's
constructor arguments are documented in the class docstring (numpydoc) or in
``__init__``'s; a dataclass's fields, which are its constructor's arguments, may be
documented under "Attributes" instead. A method that overrides a documented one without a
docstring of its own has the docstring of the method it overrides (`inspect.getdoc`),
whose entries must then name its parameters. ``*args`` and ``**kwargs`` are documented as
``*args``/``**kwargs`` (or without the stars).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
from collections.abc import Callable, Iterator

import pytest

import mavsysid

#: numpydoc section headers whose entries name parameters.
PARAMETER_SECTIONS = ("Parameters", "Other Parameters")
#: A dataclass may document its fields (its constructor's arguments) here instead.
FIELD_SECTIONS = (*PARAMETER_SECTIONS, "Attributes")

#: Public callables whose docstrings do not yet document every parameter, as
#: "module.qualname" (432 of them). This list must only shrink, to empty: fix an
#: entry's docstring and delete it (the test fails on an entry that no longer needs to be
#: here). Nothing may be added; a new public function documents its parameters.
NOT_YET_DOCUMENTED: frozenset[str] = frozenset({
    "mavsysid.cli.demo.add_arguments",
    "mavsysid.cli.demo.diagnosis_lines",
    "mavsysid.cli.demo.format_summary",
    "mavsysid.cli.demo.main",
    "mavsysid.cli.diagnose.add_arguments",
    "mavsysid.cli.diagnose.main",
    "mavsysid.cli.estimate.add_arguments",
    "mavsysid.cli.estimate.main",
    "mavsysid.cli.evaluate.add_arguments",
    "mavsysid.cli.evaluate.format_summary",
    "mavsysid.cli.evaluate.main",
    "mavsysid.cli.main.exit_code",
    "mavsysid.cli.main.main",
    "mavsysid.cli.options.add_window_arguments",
    "mavsysid.cli.options.allow_negative_values",
    "mavsysid.cli.options.parse_numbers",
    "mavsysid.cli.plan.add_arguments",
    "mavsysid.cli.plan.main",
    "mavsysid.cli.sim.add_arguments",
    "mavsysid.cli.sim.main",
    "mavsysid.cli.sim.settings_from_args",
    "mavsysid.cli.simulate.add_arguments",
    "mavsysid.cli.simulate.format_summary",
    "mavsysid.cli.simulate.main",
    "mavsysid.cli.stream.add_arguments",
    "mavsysid.cli.stream.format_summary",
    "mavsysid.cli.stream.main",
    "mavsysid.discrepancy.candidates.candidate_library",
    "mavsysid.discrepancy.diagnosis.reestimate",
    "mavsysid.discrepancy.recording.log_diagnosis",
    "mavsysid.discrepancy.recording.recording_id_for",
    "mavsysid.discrepancy.regression.Regression.__init__",
    "mavsysid.discrepancy.regression.Regression.bic",
    "mavsysid.discrepancy.regression.Regression.deviance",
    "mavsysid.discrepancy.regression.Regression.fit",
    "mavsysid.discrepancy.regression.Regression.penalty",
    "mavsysid.discrepancy.regression.Regression.stack",
    "mavsysid.discrepancy.regression.fit_theta",
    "mavsysid.discrepancy.regression.lr_p",
    "mavsysid.discrepancy.regression.profile_interval",
    "mavsysid.discrepancy.regression.refine_minimum",
    "mavsysid.discrepancy.report.augmented_vehicle",
    "mavsysid.discrepancy.report.diagnosis_to_json",
    "mavsysid.discrepancy.report.format_diagnosis",
    "mavsysid.discrepancy.report.format_reestimate",
    "mavsysid.discrepancy.report.write_diagnosis_json",
    "mavsysid.discrepancy.report_figures.effects_table",
    "mavsysid.discrepancy.report_figures.gap_table",
    "mavsysid.discrepancy.report_figures.plot_residuals",
    "mavsysid.discrepancy.resample.Resampling.block",
    "mavsysid.discrepancy.resample.Resampling.usable",
    "mavsysid.discrepancy.residual_stats.axis_rms",
    "mavsysid.discrepancy.residual_stats.ljung_box",
    "mavsysid.discrepancy.residual_stats.nis_stats",
    "mavsysid.discrepancy.residual_stats.where_large",
    "mavsysid.discrepancy.residuals.ResidualProblem.evaluate",
    "mavsysid.discrepancy.residuals.ResidualProblem.residual",
    "mavsysid.discrepancy.selection.Tie.__init__",
    "mavsysid.discrepancy.selection_model.SelectionModel.__init__",
    "mavsysid.discrepancy.selection_model.SelectionModel.candidate",
    "mavsysid.discrepancy.selection_model.SelectionModel.design",
    "mavsysid.discrepancy.selection_model.SelectionModel.profile",
    "mavsysid.discrepancy.selection_model.SelectionModel.relinearise",
    "mavsysid.estimation.results.FitChoices.__init__",
    "mavsysid.estimation.balance.choices.balance_rows_for",
    "mavsysid.estimation.balance.choices.regress",
    "mavsysid.estimation.batch.refine.factor_at_optimum",
    "mavsysid.estimation.batch.refine.shooting_problem",
    "mavsysid.estimation.batch.refine.sigma_inflation",
    "mavsysid.estimation.batch.kernels.accumulate_kernel",
    "mavsysid.estimation.batch.kernels.difference_kernel",
    "mavsysid.estimation.batch.kernels.inject_kernel",
    "mavsysid.estimation.batch.kernels.shoot_kernel",
    "mavsysid.estimation.batch.refine.ShootingProblem.__init__",
    "mavsysid.estimation.batch.refine.ShootingProblem.interval_noise",
    "mavsysid.estimation.batch.refine.ShootingProblem.jacobian",
    "mavsysid.estimation.batch.refine.ShootingProblem.normal_equations",
    "mavsysid.estimation.batch.refine.ShootingProblem.residuals",
    "mavsysid.estimation.batch.refine.apply_step",
    "mavsysid.estimation.batch.refine.node_indices",
    "mavsysid.estimation.batch.refine.whitening",
    "mavsysid.estimation.batch.kernels.BlockSystem.zeros",
    "mavsysid.estimation.batch.kernels.ThetaBorderedFactor.solve",
    "mavsysid.estimation.batch.kernels.factor",
    "mavsysid.estimation.results.Band.__init__",
    "mavsysid.estimation.balance.choices.welch_length",
    "mavsysid.estimation.filter.likelihood.has_wrench",
    "mavsysid.estimation.filter.likelihood.in_model_terms",
    "mavsysid.estimation.filter.likelihood.reference_terms",
    "mavsysid.estimation.filter.ekf.FilterOverflow.__init__",
    "mavsysid.estimation.filter.ekf.ParameterEKF.initialize",
    "mavsysid.estimation.filter.ekf.ParameterEKF.predict",
    "mavsysid.estimation.filter.ekf.ParameterEKF.run",
    "mavsysid.estimation.filter.ekf.ParameterEKF.start_segment",
    "mavsysid.estimation.filter.ekf.ParameterEKF.update",
    "mavsysid.estimation.signals.SmootherSettings.samples",
    "mavsysid.estimation.signals.acceleration_kernel",
    "mavsysid.estimation.signals.noise_gain",
    "mavsysid.estimation.flight.FlightData.segment",
    "mavsysid.estimation.flight.FlightData.time_slice",
    "mavsysid.estimation.filter.guard.decorrelated_attempt",
    "mavsysid.estimation.filter.guard.filter_attempt",
    "mavsysid.estimation.filter.guard.guarded_filter",
    "mavsysid.estimation.report.text.history_frame",
    "mavsysid.estimation.flight.InputSamples.interpolate",
    "mavsysid.estimation.filter.likelihood.scaled_noise",
    "mavsysid.estimation.balance.theta.errors_in_variables_sigma",
    "mavsysid.estimation.balance.theta.split_widening",
    "mavsysid.estimation.balance.theta.widened_sigma",
    "mavsysid.estimation.filter.guard.measured_pose_noise",
    "mavsysid.estimation.progress.report_progress",
    "mavsysid.estimation.progress.report_stage",
    "mavsysid.estimation.progress.stage_listener",
    "mavsysid.estimation.readers.samples.check_sampling",
    "mavsysid.estimation.readers.samples.gap_limit",
    "mavsysid.estimation.readers.samples.long_gaps",
    "mavsysid.estimation.readers.samples.normalise_quaternions",
    "mavsysid.estimation.readers.logs.longest_span",
    "mavsysid.estimation.readers.logs.meta_window",
    "mavsysid.estimation.readers.logs.spans_of",
    "mavsysid.estimation.report.recording.log_estimation",
    "mavsysid.estimation.report.recording.recording_id_for",
    "mavsysid.estimation.report.text.updated_vehicle",
    "mavsysid.estimation.report.text.write_estimate_json",
    "mavsysid.estimation.report.figures.plot_innovations",
    "mavsysid.estimation.report.figures.plot_parameters",
    "mavsysid.estimation.report.figures.plot_rotor_speeds",
    "mavsysid.estimation.report.figures.plot_wrench",
    "mavsysid.estimation.report.figures.save_figure",
    "mavsysid.estimation.report.figures.ReportTable.__init__",
    "mavsysid.estimation.report.figures.estimate_table",
    "mavsysid.estimation.report.figures.flight_lines",
    "mavsysid.estimation.report.figures.write_index",
    "mavsysid.estimation.robust.widened",
    "mavsysid.estimation.checks.check_kinematics",
    "mavsysid.estimation.checks.tilt_gain",
    "mavsysid.estimation.balance.rows.BalanceRows.rows",
    "mavsysid.estimation.balance.rows.BandFilter.apply",
    "mavsysid.experiments.baselines.baseline_trajectory",
    "mavsysid.experiments.baselines.excitation_spec",
    "mavsysid.experiments.baselines.excitation_violation",
    "mavsysid.experiments.baselines.oracle_plan",
    "mavsysid.experiments.baselines.paper_constraint_plan",
    "mavsysid.experiments.baselines.practitioner_excitation",
    "mavsysid.experiments.baselines.trajectory_segments",
    "mavsysid.experiments.data_efficiency.first_crossing",
    "mavsysid.experiments.data_efficiency.seconds_to_dopt",
    "mavsysid.experiments.data_efficiency.seconds_to_relative_sigma",
    "mavsysid.experiments.evaluate_job.EvaluationRun.__init__",
    "mavsysid.experiments.evaluate_job.make_specs",
    "mavsysid.experiments.evaluate_job.run_evaluation",
    "mavsysid.experiments.evaluate_job.table_notes",
    "mavsysid.experiments.evaluation.check_executor",
    "mavsysid.experiments.evaluation.last_flights",
    "mavsysid.experiments.evaluation.load_records",
    "mavsysid.experiments.evaluation.median_convergence_time",
    "mavsysid.experiments.evaluation.paired_flight_arrays",
    "mavsysid.experiments.evaluation.pending_specs",
    "mavsysid.experiments.evaluation.run_specs",
    "mavsysid.experiments.evaluation.summarise",
    "mavsysid.experiments.evaluation.write_csv",
    "mavsysid.experiments.evaluation.write_table",
    "mavsysid.experiments.evaluation_intervals.flights_beyond",
    "mavsysid.experiments.evaluation_intervals.headline_intervals",
    "mavsysid.experiments.evaluation_intervals.off_path_flights",
    "mavsysid.experiments.evaluation_intervals.saturating_flights",
    "mavsysid.experiments.evaluation_plots.write_evaluation_pngs",
    "mavsysid.experiments.evaluation_plots.write_evaluation_rrd",
    "mavsysid.experiments.experiment.controller_config",
    "mavsysid.experiments.experiment.draw_prior",
    "mavsysid.experiments.experiment.estimate_history",
    "mavsysid.experiments.experiment.filter_flight",
    "mavsysid.experiments.experiment.fly_plan",
    "mavsysid.experiments.experiment.run_experiment",
    "mavsysid.experiments.replanned_flight.concatenate",
    "mavsysid.experiments.replanned_flight.end_hover",
    "mavsysid.experiments.replanned_flight.opening_settings",
    "mavsysid.experiments.replanned_flight.rest_settings",
    "mavsysid.flight.ground.autopilot_limits.Requirement.__init__",
    "mavsysid.flight.ground.autopilot_limits.check_session_limits",
    "mavsysid.flight.ground.autopilot_limits.continuation_limit_refusals",
    "mavsysid.flight.ground.autopilot_limits.limit_parameters",
    "mavsysid.flight.ground.autopilot_limits.limits_from_parameters",
    "mavsysid.flight.ground.autopilot_limits.limits_in_effect",
    "mavsysid.flight.ground.autopilot_limits.parameter_names",
    "mavsysid.flight.ground.autopilot_limits.raised_values",
    "mavsysid.flight.ground.autopilot_limits.refusal",
    "mavsysid.flight.ground.autopilot_limits.requirements",
    "mavsysid.flight.ground.continuation.SegmentRun.__init__",
    "mavsysid.flight.ground.continuation.combined_statistics",
    "mavsysid.flight.ground.continuation.hold_while",
    "mavsysid.flight.ground.continuation.stream_segment",
    "mavsysid.flight.ground.flight_safety.install_safety",
    "mavsysid.flight.ground.flight_safety.restore_parameters",
    "mavsysid.flight.ground.geofence.VehicleOrigin.__init__",
    "mavsysid.flight.ground.geofence.fence_parameters",
    "mavsysid.flight.ground.geofence.fence_plan",
    "mavsysid.flight.ground.geofence.install_fence",
    "mavsysid.flight.ground.geofence.offset_lat_lon",
    "mavsysid.flight.ground.geofence.read_origin",
    "mavsysid.flight.ground.geofence.upload_fence_polygon",
    "mavsysid.flight.ground.link_clock.LinkClock.epoch_us",
    "mavsysid.flight.ground.link_clock.LinkClock.observe",
    "mavsysid.flight.ground.link_clock.LinkClock.received",
    "mavsysid.flight.ground.link_clock.LinkClock.sleep",
    "mavsysid.flight.ground.link_clock.LinkClock.wall",
    "mavsysid.flight.ground.link_state.VehicleState.__init__",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.add_listener",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.enum_name",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.poll",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.poll_until",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.remove_listener",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.send",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.set_ticker",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.start_heartbeat",
    "mavsysid.flight.ground.mavlink_link.MavlinkLink.wait_heartbeat",
    "mavsysid.flight.ground.mavlink_link.Ticker.fire",
    "mavsysid.flight.ground.meta_writer.MetaWriter.close",
    "mavsysid.flight.ground.meta_writer.MetaWriter.submit",
    "mavsysid.flight.ground.meta_writer.stream_flight_dir",
    "mavsysid.flight.ground.parameter_session.ParameterSession.set",
    "mavsysid.flight.ground.prearm.PrearmMonitor.__init__",
    "mavsysid.flight.ground.prearm.PrearmMonitor.on_message",
    "mavsysid.flight.ground.prearm.PrearmMonitor.wait_ready",
    "mavsysid.flight.ground.preflight.PreflightReport.__init__",
    "mavsysid.flight.ground.preflight.check_airframe",
    "mavsysid.flight.ground.preflight.check_box",
    "mavsysid.flight.ground.preflight.check_health",
    "mavsysid.flight.ground.preflight.check_plan",
    "mavsysid.flight.ground.preflight.check_rates",
    "mavsysid.flight.ground.preflight.check_takeoff_point",
    "mavsysid.flight.ground.preflight.check_vehicle",
    "mavsysid.flight.ground.rotor_watch.RotorWatch.on_message",
    "mavsysid.flight.ground.setpoints.Setpoint.advanced",
    "mavsysid.flight.ground.setpoints.SetpointLimits.refusal",
    "mavsysid.flight.ground.setpoints.SetpointLimits.violation",
    "mavsysid.flight.ground.setpoints.SmoothMove.between",
    "mavsysid.flight.ground.setpoints.SmoothMove.setpoint",
    "mavsysid.flight.ground.setpoints.TickSchedule.__init__",
    "mavsysid.flight.ground.setpoints.TickSchedule.deadline",
    "mavsysid.flight.ground.setpoints.TickSchedule.due",
    "mavsysid.flight.ground.setpoints.hold",
    "mavsysid.flight.ground.setpoints.trajectory_setpoint",
    "mavsysid.flight.ground.stream_control.FlightGuards.__init__",
    "mavsysid.flight.ground.stream_control.FlightGuards.on_message",
    "mavsysid.flight.ground.stream_control.ProgressLine.__init__",
    "mavsysid.flight.ground.stream_control.ProgressLine.update",
    "mavsysid.flight.ground.stream_control.SetpointStream.fire",
    "mavsysid.flight.ground.stream_control.SetpointStream.start",
    "mavsysid.flight.ground.stream_session.StreamSession.__init__",
    "mavsysid.flight.ground.stream_session.StreamSession.note",
    "mavsysid.flight.ground.stream_session.StreamSession.note_failure",
    "mavsysid.flight.ground.stream_session.StreamSession.note_rates",
    "mavsysid.flight.ground.stream_session.StreamSession.note_trajectory_end",
    "mavsysid.flight.ground.stream_session.StreamSession.note_trajectory_start",
    "mavsysid.flight.ground.stream_session.StreamSession.vehicle_time",
    "mavsysid.flight.ground.stream_session.open_session",
    "mavsysid.flight.ground.telemetry_recorder.ClockOffset.add",
    "mavsysid.flight.ground.telemetry_recorder.PoseSample.__init__",
    "mavsysid.flight.ground.telemetry_recorder.SetpointHistory.__init__",
    "mavsysid.flight.ground.telemetry_recorder.SetpointHistory.add",
    "mavsysid.flight.ground.telemetry_recorder.SetpointHistory.at",
    "mavsysid.flight.ground.telemetry_recorder.TelemetryRecorder.on_message",
    "mavsysid.flight.ground.trajectory_safety.check_trajectory",
    "mavsysid.flight.ground.vehicle_commands.CommandRejected.__init__",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.__init__",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.arm",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.command",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.request_message",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.set_message_interval",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.set_mode",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.takeoff",
    "mavsysid.flight.ground.vehicle_commands.VehicleCommands.wait_position",
    "mavsysid.flight.simvehicle.autopilot.SimAutopilot.arm",
    "mavsysid.flight.simvehicle.autopilot.SimAutopilot.set_mode",
    "mavsysid.flight.simvehicle.autopilot.SimAutopilot.setpoint",
    "mavsysid.flight.simvehicle.autopilot.SimAutopilot.takeoff",
    "mavsysid.flight.simvehicle.autopilot.SimAutopilot.update",
    "mavsysid.flight.simvehicle.clock.SimClock.acknowledge",
    "mavsysid.flight.simvehicle.clock.SimClock.frame_due",
    "mavsysid.flight.simvehicle.clock.SimClock.frame_sent",
    "mavsysid.flight.simvehicle.clock.is_lockstep_stamp",
    "mavsysid.flight.simvehicle.commands.CommandHandler.command",
    "mavsysid.flight.simvehicle.commands.CommandHandler.request_data_stream",
    "mavsysid.flight.simvehicle.commands.CommandHandler.set_mode_message",
    "mavsysid.flight.simvehicle.endpoint.SimEndpoint.call_soon",
    "mavsysid.flight.simvehicle.endpoint.SimEndpoint.close",
    "mavsysid.flight.simvehicle.fence.FenceMonitor.check",
    "mavsysid.flight.simvehicle.fence.FenceMonitor.outside",
    "mavsysid.flight.simvehicle.fence.FenceMonitor.prearm_failure",
    "mavsysid.flight.simvehicle.fence.FenceMonitor.upload",
    "mavsysid.flight.simvehicle.fence.FenceRegions.__init__",
    "mavsysid.flight.simvehicle.fence.FenceRegions.breached",
    "mavsysid.flight.simvehicle.fence.FenceResponse.__init__",
    "mavsysid.flight.simvehicle.fence.fence_names",
    "mavsysid.flight.simvehicle.fence.fence_regions",
    "mavsysid.flight.simvehicle.fence.guided_timeout",
    "mavsysid.flight.simvehicle.fence.inside_polygon",
    "mavsysid.flight.simvehicle.fence.offboard_loss_modes",
    "mavsysid.flight.simvehicle.geodesy.enu_to_lat_lon",
    "mavsysid.flight.simvehicle.geodesy.lat_lon_to_enu",
    "mavsysid.flight.simvehicle.link.open_link",
    "mavsysid.flight.simvehicle.params.Parameter.__init__",
    "mavsysid.flight.simvehicle.params.ParameterProtocol.decode",
    "mavsysid.flight.simvehicle.params.ParameterProtocol.encode",
    "mavsysid.flight.simvehicle.params.ParameterProtocol.handle",
    "mavsysid.flight.simvehicle.params.ParameterProtocol.value_message",
    "mavsysid.flight.simvehicle.params.ParameterTable.add_listener",
    "mavsysid.flight.simvehicle.params.ParameterTable.at",
    "mavsysid.flight.simvehicle.params.ParameterTable.get",
    "mavsysid.flight.simvehicle.params.ParameterTable.index",
    "mavsysid.flight.simvehicle.params.ParameterTable.set",
    "mavsysid.flight.simvehicle.params.default_parameters",
    "mavsysid.flight.simvehicle.physics.SimVehicle.step",
    "mavsysid.flight.simvehicle.physics.TruthLog.finish",
    "mavsysid.flight.simvehicle.physics.TruthLog.record",
    "mavsysid.flight.simvehicle.reference.hold_target",
    "mavsysid.flight.simvehicle.reference.shape_step",
    "mavsysid.flight.simvehicle.services.MissionProtocol.handle",
    "mavsysid.flight.simvehicle.services.ftp_refusal",
    "mavsysid.flight.simvehicle.services.timesync_reply",
    "mavsysid.flight.simvehicle.setpoint_input.SetpointTracker.age",
    "mavsysid.flight.simvehicle.setpoint_input.SetpointTracker.apply_latest",
    "mavsysid.flight.simvehicle.setpoint_input.SetpointTracker.check_timeout",
    "mavsysid.flight.simvehicle.setpoint_input.SetpointTracker.receive",
    "mavsysid.flight.simvehicle.setpoint_input.SetpointTracker.streaming",
    "mavsysid.flight.simvehicle.sim_session.SimSummary.__init__",
    "mavsysid.flight.simvehicle.telemetry.MessageScheduler.due",
    "mavsysid.flight.simvehicle.telemetry.MessageScheduler.interval_us",
    "mavsysid.flight.simvehicle.telemetry.MessageScheduler.schedulable",
    "mavsysid.flight.simvehicle.telemetry.MessageScheduler.set_interval",
    "mavsysid.flight.simvehicle.telemetry.MessageScheduler.set_rate_hz",
    "mavsysid.flight.simvehicle.telemetry.TelemetryBuilder.build",
    "mavsysid.flight.simvehicle.telemetry.TelemetryBuilder.can_build",
    "mavsysid.flight.simvehicle.telemetry.default_rates",
    "mavsysid.pipeline.demo.DemoResult.__init__",
    "mavsysid.pipeline.demo.DemoRound.__init__",
    "mavsysid.pipeline.diagnose.DiagnoseRun.__init__",
    "mavsysid.pipeline.estimate.EstimateRun.__init__",
    "mavsysid.pipeline.simulate.OfflineFlight.__init__",
    "mavsysid.pipeline.stream.StreamOutcome.__init__",
    "mavsysid.planner.baseline.plan_random",
    "mavsysid.planner.belief.EdgeTransfer.__init__",
    "mavsysid.planner.belief.apply_transfer",
    "mavsysid.planner.belief.apply_transfer_logdet",
    "mavsysid.planner.belief.edge_transfer",
    "mavsysid.planner.belief.propagate_final",
    "mavsysid.planner.belief.propagate_steps",
    "mavsysid.planner.belief.riccati_final",
    "mavsysid.planner.belief.star",
    "mavsysid.planner.belief.steps_transfer",
    "mavsysid.planner.bernstein.bernstein_matrix",
    "mavsysid.planner.bernstein.linear_violation",
    "mavsysid.planner.bernstein.range_violation",
    "mavsysid.planner.bernstein.square_norm",
    "mavsysid.planner.bernstein.square_weights",
    "mavsysid.planner.bernstein.to_bernstein",
    "mavsysid.planner.best_flight.best_path",
    "mavsysid.planner.best_flight.refine_best",
    "mavsysid.planner.feasibility.check_rotor_headroom",
    "mavsysid.planner.feasibility.rotor_square_range",
    "mavsysid.planner.feasibility.segment_slack",
    "mavsysid.planner.gradient_refine.GradientRefiner.gradient_step",
    "mavsysid.planner.gradient_refine.block_gradient",
    "mavsysid.planner.graph.Belief.__init__",
    "mavsysid.planner.graph.Edge.__init__",
    "mavsysid.planner.graph.Vertex.__init__",
    "mavsysid.planner.graph.Vertex.keep",
    "mavsysid.planner.graph.logdet",
    "mavsysid.planner.graph_search.GraphSearch.__init__",
    "mavsysid.planner.graph_search.GraphSearch.add_edge",
    "mavsysid.planner.graph_search.GraphSearch.add_vertex",
    "mavsysid.planner.graph_search.GraphSearch.append",
    "mavsysid.planner.graph_search.GraphSearch.belief",
    "mavsysid.planner.graph_search.GraphSearch.consider",
    "mavsysid.planner.graph_search.GraphSearch.dopt",
    "mavsysid.planner.graph_search.GraphSearch.edge_transfer",
    "mavsysid.planner.graph_search.GraphSearch.feasible",
    "mavsysid.planner.graph_search.GraphSearch.flight_dopt",
    "mavsysid.planner.graph_search.GraphSearch.kept_transfer",
    "mavsysid.planner.graph_search.GraphSearch.propagate",
    "mavsysid.planner.graph_search.GraphSearch.propagate_segments",
    "mavsysid.planner.graph_search.GraphSearch.report",
    "mavsysid.planner.graph_search.GraphSearch.sample_duration",
    "mavsysid.planner.graph_search.GraphSearch.stop_at",
    "mavsysid.planner.graph_search.GraphSearch.transfer_of",
    "mavsysid.planner.graph_search.GraphSearch.try_fixed",
    "mavsysid.planner.kinematic_check.check_limits",
    "mavsysid.planner.kinematic_check.exceeded_limits",
    "mavsysid.planner.kinematic_check.segment_peaks",
    "mavsysid.planner.plan_file.plan_file_for",
    "mavsysid.planner.plan_file.write_trajectory",
    "mavsysid.planner.plan_request.rotor_clearance",
    "mavsysid.planner.recording.log_plan",
    "mavsysid.planner.recording.recording_id_for",
    "mavsysid.planner.recording.time_colors",
    "mavsysid.planner.refine.PathRefiner.accept",
    "mavsysid.planner.refine.PathRefiner.candidate",
    "mavsysid.planner.refine.PathRefiner.price",
    "mavsysid.planner.refine.RefinablePath.__init__",
    "mavsysid.planner.refine.StopChoice.__init__",
    "mavsysid.planner.refine.split_path",
    "mavsysid.planner.plan_result.PlanProgress.__init__",
    "mavsysid.planner.robust_plan.ConfidentPlan.__init__",
    "mavsysid.planner.robust_plan.plan_most_confident",
    "mavsysid.planner.rrbt.plan",
    "mavsysid.planner.rrbt.search_graph",
    "mavsysid.planner.sample_slacks.sample_slacks",
    "mavsysid.planner.sample_slacks.slab_spread",
    "mavsysid.planner.search_setup.initial_covariance",
    "mavsysid.planner.search_setup.search_model",
    "mavsysid.planner.search_setup.segment_trajectory",
    "mavsysid.planner.search_setup.warm_up",
    "mavsysid.planner.segments.Segment.flat_outputs",
    "mavsysid.planner.segments.Segment.state_at",
    "mavsysid.planner.segments.VertexState.hover",
    "mavsysid.planner.segments.snap_cost",
    "mavsysid.planner.segments.to_piecewise",
    "mavsysid.planner.segments.yaw_rate_cost",
    "mavsysid.planner.yaw_branch.nearest_yaw_branch",
    "mavsysid.planner.yaw_branch.shift_segment_yaw",
    "mavsysid.planner.yaw_branch.shift_vertex_yaw",
    "mavsysid.vehicle.model_effects.GroundEffect.gain",
    "mavsysid.vehicle.model_effects.effect_from_values",
    "mavsysid.vehicle.model_effects.parse_effect",
})

_HEADER = re.compile(r"^\s*-{3,}\s*$")
_ENTRY = re.compile(r"^(\*{0,2}[A-Za-z_][A-Za-z0-9_]*(?:\s*,\s*\*{0,2}[A-Za-z_][A-Za-z0-9_]*)*)"
                    r"\s*(?::.*)?$")


def _modules() -> list[str]:
    """Import names of every module of the installed package."""
    names = [mavsysid.__name__]
    for info in pkgutil.walk_packages(mavsysid.__path__, prefix="mavsysid."):
        names.append(info.name)
    for sub in ("vehicle", "formats", "planner", "flight", "estimation", "discrepancy",
                "pipeline", "experiments"):
        package = importlib.import_module(f"mavsysid.{sub}")
        names.append(package.__name__)
        names += [info.name for info in
                  pkgutil.walk_packages(package.__path__, prefix=f"{package.__name__}.")]
    return sorted(set(n for n in names if not n.endswith("__main__")))


def documented(doc: str | None, sections: tuple[str, ...] = PARAMETER_SECTIONS) -> set[str]:
    """The names with an entry in the given numpydoc sections of ``doc``.

    Parameters
    ----------
    doc : str or None
        A docstring (indented as written; `inspect.cleandoc` is applied).
    sections : tuple of str
        The section headers whose entries count.
    """
    lines = inspect.cleandoc(doc or "").splitlines()
    names: set[str] = set()
    section = None
    for i, line in enumerate(lines):
        if i + 1 < len(lines) and _HEADER.match(lines[i + 1]) and line.strip():
            section = line.strip()
            continue
        if section not in sections or _HEADER.match(line) or not line.strip():
            continue
        if line[0].isspace():
            continue  # an entry's description
        match = _ENTRY.match(line.strip())
        if match:
            names.update(n.strip().lstrip("*") for n in match.group(1).split(","))
    return names


def _parameters(func: Callable) -> list[str]:
    """Parameter names of ``func`` to document (no ``self``/``cls``)."""
    func = getattr(func, "py_func", func)  # a numba kernel: its Python function
    try:
        signature = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    names = [p.name for p in signature.parameters.values()]
    if names and names[0] in ("self", "cls"):
        names = names[1:]
    return names


def _callables() -> Iterator[tuple[str, list[str], set[str]]]:
    """(name, parameters, documented names) of every public function and method."""
    for module_name in _modules():
        module = importlib.import_module(module_name)
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name, None)
            if getattr(obj, "__module__", None) != module_name:
                continue  # a re-export, or a constant
            qualname = f"{module_name}.{name}"
            if inspect.isclass(obj):
                yield from _class_callables(qualname, obj)
            elif callable(obj) and (inspect.isfunction(obj) or hasattr(obj, "py_func")):
                yield qualname, _parameters(obj), documented(
                    getattr(obj, "py_func", obj).__doc__)


def _class_callables(qualname: str, cls: type) -> Iterator[tuple[str, list[str], set[str]]]:
    """The constructor and the public methods a class defines itself."""
    init = cls.__dict__.get("__init__")
    if dataclasses.is_dataclass(cls) and inspect.isfunction(init) and (
            init.__code__.co_filename == "<string>"):  # the generated constructor
        fields = [f.name for f in dataclasses.fields(cls) if f.init]
        yield f"{qualname}.__init__", fields, documented(cls.__doc__, FIELD_SECTIONS)
    elif inspect.isfunction(init) and init.__qualname__ == f"{cls.__qualname__}.__init__":
        yield (f"{qualname}.__init__", _parameters(init),
               documented(cls.__doc__) | documented(init.__doc__))
    for attr, value in cls.__dict__.items():
        if attr.startswith("_"):
            continue
        func = value.__func__ if isinstance(value, (staticmethod, classmethod)) else value
        if inspect.isfunction(func):
            # An override without a docstring has its interface's (`inspect.getdoc`).
            yield (f"{qualname}.{attr}", _parameters(func),
                   documented(inspect.getdoc(getattr(cls, attr))))


@pytest.fixture(scope="module")
def missing() -> dict[str, list[str]]:
    """Every public callable with undocumented parameters → those parameters."""
    out = {}
    for name, params, doc in _callables():
        absent = [p for p in params if p not in doc]
        if absent:
            out[name] = absent
    return out


def test_every_public_parameter_is_documented(missing: dict[str, list[str]]) -> None:
    """Each public function's and method's parameters have numpydoc "Parameters" entries."""
    new = {name: params for name, params in missing.items() if name not in NOT_YET_DOCUMENTED}
    assert not new, "parameters without a 'Parameters' entry:\n" + "\n".join(
        f"  {name}: {', '.join(params)}" for name, params in sorted(new.items()))


def test_allow_list_only_shrinks(missing: dict[str, list[str]]) -> None:
    """Every allow-listed callable still lacks a parameter entry (a fixed one leaves the list)."""
    fixed = sorted(NOT_YET_DOCUMENTED - set(missing))
    assert not fixed, "documented now, remove from NOT_YET_DOCUMENTED: " + ", ".join(fixed)


@pytest.mark.parametrize(("doc", "expected"), [
    ("One line.\n\nParameters\n----------\nx : float\n    Metres.\ny, z : int\n"
     "    Counts.\n*args\n    More.\n\nReturns\n-------\nw : float\n    Not a parameter.",
     {"x", "y", "z", "args"}),
    ("One line.\n\n    Parameters\n    ----------\n    a\n        Text with b : c inside.\n",
     {"a"}),
    ("One line, no sections: x and y named in prose.", set()),
    ("One line.\n\nAttributes\n----------\nx : float\n    Metres.", set()),
])
def test_parameter_entries_are_parsed(doc: str, expected: set[str]) -> None:
    """The section parser finds exactly the entries of "Parameters" (not Returns, prose)."""
    assert documented(doc) == expected
