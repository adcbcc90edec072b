"""Telemetry of the simulated vehicle: message builders and the message-interval scheduler.

Defaults follow ArduPilot's SRx stream rates (HEARTBEAT 1 Hz, SYS_STATUS 1 Hz,
SYSTEM_TIME 1 Hz, ATTITUDE 4 Hz, LOCAL_POSITION_NED and GLOBAL_POSITION_INT 3 Hz, ESC
telemetry 1 Hz, EKF_STATUS_REPORT 1 Hz on ArduPilot, EXTENDED_SYS_STATE 1 Hz,
ATTITUDE_QUATERNION off); MAV_CMD_SET_MESSAGE_INTERVAL changes one message (at most
250 Hz), REQUEST_DATA_STREAM and the SR0_* parameters a whole ArduPilot stream group.
Messages due in the same tick go out in a fixed order, LOCAL_POSITION_NED last, so that
a recorder sees the attitude and ESC rpm of a sample before its position. Due times are
multiples of the interval in sim time, so a 50 Hz message is stamped 0, 20, 40, … ms.

The IMU goes out as its autopilot sends it, off until asked for (SET_MESSAGE_INTERVAL,
or ArduPilot's RAW_SENSORS stream group): ArduPilot RAW_IMU (its first IMU in mG and
mrad/s, ``GCS_MAVLINK::send_raw_imu``, at ``time_usec`` since boot); PX4 HIGHRES_IMU (SI,
``fields_updated`` flagging the accelerometer and gyro) and SCALED_IMU (mG, mrad/s). At
most 250 Hz, like every message here.

Everything is stamped with the sim time of the tick (time_boot_ms), converted to
NED/FRD here, and built from the published (noisy) pose and IMU. The local NED origin is the
world ENU origin (0, 0, 0); home is the start position; GLOBAL_POSITION_INT places the
origin at 47.397742° N, 8.545594° E, 488 m (PX4 SITL's default).
"""

from __future__ import annotations

import math
import time

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.simvehicle.autopilot import SimAutopilot
from mavsysid.flight.simvehicle.fence import ALT_MAX, CIRCLE, POLYGON
from mavsysid.flight.simvehicle.geodesy import enu_to_lat_lon
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.flight.simvehicle.physics import ORIGIN
from mavsysid.formats.motor_curve import pwm_from_rotor_speed
from mavsysid.formats.tlog import STANDARD_GRAVITY
from mavsysid.vehicle.frames import enu_to_ned, flu_to_frd, quaternion_enu_to_ned, yaw_enu_to_ned
from mavsysid.vehicle.motor_order import output_order
from mavsysid.vehicle.rotation import quat_to_euler

__all__ = [
    "ORIGIN",
    "MessageScheduler",
    "TelemetryBuilder",
    "ardupilot_streams",
    "default_rates",
]

M = mavlink
MIN_INTERVAL_US = 4000  # 250 Hz
_ESC_IDS = (M.MAVLINK_MSG_ID_ESC_TELEMETRY_1_TO_4, M.MAVLINK_MSG_ID_ESC_TELEMETRY_5_TO_8,
            M.MAVLINK_MSG_ID_ESC_TELEMETRY_9_TO_12)
_ESC_CLASSES = (M.MAVLink_esc_telemetry_1_to_4_message, M.MAVLink_esc_telemetry_5_to_8_message,
                M.MAVLink_esc_telemetry_9_to_12_message)
_IMU_IDS = (M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_SCALED_IMU, M.MAVLINK_MSG_ID_RAW_IMU)
#: Send order within a tick.
_ORDER = (M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_SYSTEM_TIME,
          M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
          M.MAVLINK_MSG_ID_FENCE_STATUS,
          M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, *_ESC_IDS,
          *_IMU_IDS, M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
          M.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
#: HIGHRES_IMU.fields_updated: x, y, z of the accelerometer and of the gyro.
_HIGHRES_IMU_FIELDS = 0b111111
_POSITION_IDS = frozenset((M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                           M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_HOME_POSITION,
                           M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN))
_EKF_GOOD = (M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_HORIZ_REL
             | M.EKF_POS_HORIZ_ABS | M.EKF_POS_VERT_ABS | M.EKF_PRED_POS_HORIZ_REL
             | M.EKF_PRED_POS_HORIZ_ABS)
_EKF_NO_POSITION = M.EKF_ATTITUDE | M.EKF_VELOCITY_VERT | M.EKF_CONST_POS_MODE
_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
            | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_SENSOR_BATTERY)
_POSITION_SENSORS = (M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
                     | M.MAV_SYS_STATUS_PREARM_CHECK)
_MAV_TYPES = {3: M.MAV_TYPE_TRICOPTER, 4: M.MAV_TYPE_QUADROTOR, 6: M.MAV_TYPE_HEXAROTOR,
              8: M.MAV_TYPE_OCTOROTOR}


def ardupilot_streams() -> dict[int, tuple[int, ...]]:
    """ArduPilot's stream groups (MAV_DATA_STREAM_*) over the simulated messages."""
    return {
        M.MAV_DATA_STREAM_EXTENDED_STATUS: (M.MAVLINK_MSG_ID_SYS_STATUS,
                                            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                                            M.MAVLINK_MSG_ID_FENCE_STATUS),
        M.MAV_DATA_STREAM_POSITION: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                                     M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
        M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE,),
        M.MAV_DATA_STREAM_RC_CHANNELS: (M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,),
        M.MAV_DATA_STREAM_EXTRA3: (M.MAVLINK_MSG_ID_SYSTEM_TIME,
                                   M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, *_ESC_IDS),
        M.MAV_DATA_STREAM_RAW_SENSORS: (M.MAVLINK_MSG_ID_RAW_IMU,),
    }


class MessageScheduler:
    """Which periodic messages are due at a tick.

    Parameters
    ----------
    defaults_hz : dict
        Message id → default rate, Hz (0: off). Only these messages can be scheduled.
    """

    def __init__(self, defaults_hz: dict[int, float]) -> None:
        self.order = tuple(i for i in _ORDER if i in defaults_hz)
        self._default = {i: _interval_us(hz) for i, hz in defaults_hz.items()}
        self._interval = dict(self._default)
        self._next = {i: 0 for i in self.order}
        self._next_any = 0

    def schedulable(self, msg_id: int) -> bool:
        """Whether ``msg_id`` can be sent periodically."""
        return msg_id in self._interval

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL's value: µs, −1 when off, 0 when not available."""
        if msg_id not in self._interval:
            return 0
        return self._interval[msg_id] or -1

    def set_interval(self, msg_id: int, interval_us: float, now_us: int) -> bool:
        """SET_MESSAGE_INTERVAL semantics (0: default, < 0: off); False if not schedulable.

        ESC_TELEMETRY_1_TO_4 sets the other ESC blocks too.
        """
        if msg_id not in self._interval:
            return False
        if interval_us == 0:
            value = self._default[msg_id]
        elif interval_us < 0:
            value = 0
        else:
            value = max(round(interval_us), MIN_INTERVAL_US)
        ids = [i for i in _ESC_IDS if i in self._interval] if msg_id == _ESC_IDS[0] else [msg_id]
        for i in ids:
            self._interval[i] = value
            if value:
                self._next[i] = -(-now_us // value) * value  # next multiple of the interval
        self._next_any = min(self._next.values())
        return True

    def set_rate_hz(self, msg_ids, rate_hz: float, now_us: int) -> None:
        """Set several messages to one rate (a stream group), 0 Hz: off."""
        for i in msg_ids:
            if i in self._interval:
                self.set_interval(i, _interval_us(rate_hz) if rate_hz > 0 else -1, now_us)

    def due(self, now_us: int) -> list[int]:
        """The messages due at ``now_us``, in send order (their next due times advance)."""
        if now_us < self._next_any:
            return []
        out = []
        nxt, interval = self._next, self._interval
        for i in self.order:
            step = interval[i]
            if step and now_us >= nxt[i]:
                out.append(i)
                n = nxt[i] + step
                nxt[i] = n if n > now_us else (now_us // step + 1) * step
        self._next_any = min((nxt[i] for i in self.order if interval[i]), default=1 << 62)
        return out


def _interval_us(rate_hz: float) -> int:
    return 0 if rate_hz <= 0 else max(round(1e6 / rate_hz), MIN_INTERVAL_US)


def default_rates(autopilot: Autopilot, rotor_count: int) -> dict[int, float]:
    """Default rates, Hz, of the periodic messages (see the module docstring)."""
    rates = {M.MAVLINK_MSG_ID_HEARTBEAT: 1.0, M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
             M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
             M.MAVLINK_MSG_ID_ATTITUDE: 4.0, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.0,
             M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 3.0, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 3.0,
             M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 0.0}
    for block in range(min(3, -(-rotor_count // 4))):
        rates[_ESC_IDS[block]] = 1.0
    if autopilot is Autopilot.ARDUPILOT:
        rates[M.MAVLINK_MSG_ID_EKF_STATUS_REPORT] = 1.0
        rates[M.MAVLINK_MSG_ID_FENCE_STATUS] = 1.0  # sent only while the fence is enabled
        rates[M.MAVLINK_MSG_ID_RAW_IMU] = 0.0
    else:
        rates[M.MAVLINK_MSG_ID_HIGHRES_IMU] = 0.0
        rates[M.MAVLINK_MSG_ID_SCALED_IMU] = 0.0
    return rates


class TelemetryBuilder:
    """Builds the vehicle's messages from the autopilot and vehicle state of this tick.

    Parameters
    ----------
    autopilot : SimAutopilot
    """

    def __init__(self, autopilot: SimAutopilot) -> None:
        self.ap = autopilot
        self.vehicle = autopilot.vehicle
        config = self.vehicle.config
        k = config.rotor_count
        #: Config rotor of each motor output (the vehicle file's ``[autopilot] frame``).
        self.outputs = output_order(config.rotor_positions, config.rotor_directions,
                                    config.autopilot_frame)
        self.mav_type = _MAV_TYPES.get(k, M.MAV_TYPE_GENERIC)
        self._unix0 = time.time()
        self._esc_count = 0
        self._builders = {
            M.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            M.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            M.MAVLINK_MSG_ID_SYSTEM_TIME: self.system_time,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            M.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            M.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
            M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: self.servo_output_raw,
        }
        for block in range(min(3, -(-k // 4))):
            self._builders[_ESC_IDS[block]] = self._esc_builder(block)
        if autopilot.ardupilot:
            self._builders[M.MAVLINK_MSG_ID_EKF_STATUS_REPORT] = self.ekf_status_report
            self._builders[M.MAVLINK_MSG_ID_FENCE_STATUS] = self.fence_status
            self._builders[M.MAVLINK_MSG_ID_RAW_IMU] = self.raw_imu
        else:
            self._builders[M.MAVLINK_MSG_ID_HIGHRES_IMU] = self.highres_imu
            self._builders[M.MAVLINK_MSG_ID_SCALED_IMU] = self.scaled_imu

    def can_build(self, msg_id: int) -> bool:
        """Whether this vehicle has such a message at all."""
        return msg_id in self._builders

    def build(self, msg_id: int):
        """The message now, or None (unknown, or a position message without position)."""
        if msg_id in _POSITION_IDS and not self.ap.position_ok():
            return None
        builder = self._builders.get(msg_id)
        return None if builder is None else builder()

    # --- helpers ------------------------------------------------------------------------
    def _ms(self) -> int:
        return self.vehicle.time_us // 1000

    def _pose_ned(self) -> tuple[list[float], list[float], list[float]]:
        """Published position NED, attitude q_ned_frd, velocity NED."""
        p, q, _ = self.vehicle.measured()
        return (enu_to_ned(p).tolist(), quaternion_enu_to_ned(q).tolist(),
                enu_to_ned(self.vehicle.velocity()).tolist())

    def _rates_frd(self) -> tuple[float, float, float]:
        return tuple(flu_to_frd(self.vehicle.body_rates).tolist())

    def _global(self, p_ned) -> tuple[int, int, int]:
        lat, lon = enu_to_lat_lon(p_ned[1], p_ned[0])
        return round(lat * 1e7), round(lon * 1e7), round((ORIGIN[2] - p_ned[2]) * 1000.0)

    # --- messages -----------------------------------------------------------------------
    def heartbeat(self):
        ap = self.ap
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if ap.spec.kind not in ("manual", "hold"):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if ap.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        status = M.MAV_STATE_ACTIVE if ap.armed else M.MAV_STATE_STANDBY
        return M.MAVLink_heartbeat_message(self.mav_type, ap.autopilot.value, base, ap.mode,
                                           status, 3)

    def sys_status(self):
        # The geofence bit as AC_Fence::sys_status_*: present with a fence, enabled when
        # also switched on with an action, healthy unless breached (also with no fence:
        # ground stations read a missing health bit as a breach).
        fence_present, fence_enabled, fence_healthy = self.ap.fence.sys_status()
        geofence = M.MAV_SYS_STATUS_GEOFENCE
        health = (_SENSORS | (geofence if fence_healthy else 0)
                  | (_POSITION_SENSORS if self.ap.position_ok() else 0))
        present = _SENSORS | _POSITION_SENSORS | (geofence if fence_present else 0)
        enabled = (present & ~geofence) | (geofence if fence_enabled else 0)
        current = (1500 if not self.vehicle.landed else 100) if self.ap.armed else 0
        return M.MAVLink_sys_status_message(present, enabled, health, 150, 16200, current, 95,
                                            0, 0, 0, 0, 0, 0)

    def system_time(self):
        unix = self._unix0 + self.vehicle.time_us * 1e-6
        return M.MAVLink_system_time_message(int(unix * 1e6), self._ms())

    def extended_sys_state(self):
        ap = self.ap
        if ap.land_undetected:
            state = M.MAV_LANDED_STATE_LANDING
        elif self.vehicle.landed:
            state = M.MAV_LANDED_STATE_ON_GROUND
        elif ap.taking_off:
            state = M.MAV_LANDED_STATE_TAKEOFF
        elif ap.landing:
            state = M.MAV_LANDED_STATE_LANDING
        else:
            state = M.MAV_LANDED_STATE_IN_AIR
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, state)

    def fence_status(self):
        """FENCE_STATUS as Copter's fence_send_mavlink_status: only while the fence is
        enabled; a boundary (circle, polygon) breach outranks an altitude one."""
        fence = self.ap.fence
        if not fence.enabled():
            return None
        kind = (M.FENCE_BREACH_BOUNDARY if fence.breaches & (CIRCLE | POLYGON) else
                M.FENCE_BREACH_MAXALT if fence.breaches & ALT_MAX else M.FENCE_BREACH_NONE)
        return M.MAVLink_fence_status_message(int(fence.breaches != 0), fence.breach_count,
                                              kind, round(fence.breach_time * 1000.0))

    def ekf_status_report(self):
        flags = _EKF_GOOD if self.ap.position_ok() else _EKF_NO_POSITION
        return M.MAVLink_ekf_status_report_message(flags, 0.02, 0.01, 0.01, 0.03, 0.0)

    def attitude(self):
        _, q, _ = self._pose_ned()
        roll, pitch, yaw = (float(a) for a in quat_to_euler(q))
        return M.MAVLink_attitude_message(self._ms(), roll, pitch, yaw, *self._rates_frd())

    def attitude_quaternion(self):
        _, q, _ = self._pose_ned()
        return M.MAVLink_attitude_quaternion_message(self._ms(), *q, *self._rates_frd(),
                                                     [0.0, 0.0, 0.0, 0.0])

    def local_position_ned(self):
        p, _, v = self._pose_ned()
        return M.MAVLink_local_position_ned_message(self._ms(), *p, *v)

    def global_position_int(self):
        p, _, v = self._pose_ned()
        lat, lon, alt = self._global(p)
        rel = round((-p[2] - self.ap.home[2]) * 1000.0)
        heading = math.degrees(yaw_enu_to_ned(self.vehicle.yaw())) % 360.0
        vel = [max(-32768, min(32767, round(c * 100.0))) for c in v]
        return M.MAVLink_global_position_int_message(self._ms(), lat, lon, alt, rel, *vel,
                                                     round(heading * 100.0) % 36000)

    def home_position(self):
        h = self.ap.home
        ned = [float(h[1]), float(h[0]), float(-h[2])]
        lat, lon, alt = self._global(ned)
        return M.MAVLink_home_position_message(lat, lon, alt, *ned, [1.0, 0.0, 0.0, 0.0],
                                               0.0, 0.0, 0.0, self.vehicle.time_us)

    def gps_global_origin(self):
        """The local frame's origin (the world origin), as the EKF origin."""
        lat, lon, alt = self._global([0.0, 0.0, 0.0])
        return M.MAVLink_gps_global_origin_message(lat, lon, alt, self.vehicle.time_us)

    def autopilot_version(self):
        caps = (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED)
        if self.ap.ardupilot:
            caps |= M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            version = (4 << 24) | (5 << 16) | (7 << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
        else:
            caps |= M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            version = (1 << 24) | (14 << 16) | (3 << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
        custom = list(b"mavsysid")
        return M.MAVLink_autopilot_version_message(caps, version, 0, 0, 0, custom, [0] * 8,
                                                   [0] * 8, 0, 0, 0x6D617673, [0] * 18)

    def _imu_frd(self) -> tuple[list[float], list[float]]:
        """The IMU's gyro (rad/s) and specific force (m/s²) at this tick, body FRD."""
        gyro, accel = self.vehicle.imu_measured()
        return flu_to_frd(gyro).tolist(), flu_to_frd(accel).tolist()

    def _milli(self) -> list[int]:
        """The IMU as SCALED_IMU / RAW_IMU carry it: mG, then mrad/s (int16)."""
        gyro, accel = self._imu_frd()
        values = [a * 1000.0 / STANDARD_GRAVITY for a in accel] + [g * 1000.0 for g in gyro]
        return [max(-32768, min(32767, round(v))) for v in values]

    def highres_imu(self):
        gyro, accel = self._imu_frd()
        return M.MAVLink_highres_imu_message(self.vehicle.time_us, *accel, *gyro, 0.0, 0.0, 0.0,
                                             0.0, 0.0, 0.0, 45.0, _HIGHRES_IMU_FIELDS, 0)

    def scaled_imu(self):
        return M.MAVLink_scaled_imu_message(self._ms(), *self._milli(), 0, 0, 0, 4500)

    def raw_imu(self):
        return M.MAVLink_raw_imu_message(self.vehicle.time_us, *self._milli(), 0, 0, 0, 0, 4500)

    def servo_output_raw(self):
        """The motor outputs, µs: the controller's commanded speeds through the vehicle
        file's [motor] curve, in motor-output order (a weak motor shows here working
        harder, while its ESC rpm shows the speed it reaches)."""
        pwm = pwm_from_rotor_speed(self.vehicle.n_cmd[list(self.outputs)], self.vehicle.config)
        raw = [round(float(v)) for v in pwm[:16]] + [0] * (16 - min(16, pwm.size))
        return M.MAVLink_servo_output_raw_message(self.vehicle.time_us & 0xFFFFFFFF, 0, *raw)

    def _esc_builder(self, block: int):
        cls = _ESC_CLASSES[block]
        k = self.vehicle.config.rotor_count
        rotors = [self.outputs[i] for i in range(4 * block, 4 * block + 4) if i < k]
        scale = 60.0 / (2.0 * math.pi)

        def build():
            _, _, n = self.vehicle.measured()
            rpm = [0, 0, 0, 0]
            for j, i in enumerate(rotors):
                rpm[j] = min(65535, max(0, round(float(n[i]) * scale)))
            self._esc_count = (self._esc_count + 1) & 0xFFFF
            on = [1 if j < len(rotors) else 0 for j in range(4)]
            return cls([30 * o for o in on], [1620 * o for o in on], [0, 0, 0, 0],
                       [0, 0, 0, 0], rpm, [self._esc_count * o for o in on])

        return build
