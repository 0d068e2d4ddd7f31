"""MAVLink frame conversions and protocol constants, as small pure functions (no pymavlink).

Our world frame is ENU (x east, y north, theta CCW from east) and our body frame is FLU
(vx forward, vy left, wz CCW), like ROS. MAVLink's local frame is NED (x north, y east, z down,
yaw clockwise from north) and its body frame is FRD (x forward, y right, z down). Both changes
are reflections, so each conversion is its own inverse:

- world pose:  x_n = y_e, y_n = x_e, yaw_ned = pi/2 - theta_enu (wrapped to [-pi, pi])
- world velocity: (vn, ve) = (vy_e, vx_e), yaw rate changes sign
- body twist:  vx same, vy and wz change sign

The vehicle's local NED origin is assumed to be the world origin (a mocap-fed EKF whose origin is
the mocap origin); the emulator does the same.

The constants below (mode numbers, type masks) are shared by the adapter and the emulator so the
two can never drift apart.
"""

from __future__ import annotations

import math

from controller.wire import wrap_angle

# --------------------------------------------------------------------------- conversions


def enu_to_ned_pose(x: float, y: float, theta: float) -> tuple[float, float, float]:
    """World ENU pose (m, m, rad CCW from east) -> local NED (north m, east m, yaw rad CW from
    north)."""
    return y, x, wrap_angle(math.pi / 2.0 - theta)


def ned_to_enu_pose(north: float, east: float, yaw: float) -> tuple[float, float, float]:
    """Local NED (north m, east m, yaw rad CW from north) -> world ENU (x m, y m, theta rad CCW
    from east)."""
    return east, north, wrap_angle(math.pi / 2.0 - yaw)


def enu_to_ned_velocity(vx: float, vy: float, wz: float) -> tuple[float, float, float]:
    """World ENU velocity (m/s east, m/s north, rad/s CCW) -> NED (m/s north, m/s east, rad/s
    CW)."""
    return vy, vx, -wz


def ned_to_enu_velocity(vn: float, ve: float, yaw_rate: float) -> tuple[float, float, float]:
    """NED velocity (m/s north, m/s east, rad/s CW) -> world ENU (m/s east, m/s north, rad/s
    CCW)."""
    return ve, vn, -yaw_rate


def flu_to_frd(vx: float, vy: float, wz: float) -> tuple[float, float, float]:
    """Body FLU twist (m/s forward, m/s left, rad/s CCW) -> FRD (m/s forward, m/s right, rad/s
    CW)."""
    return vx, -vy, -wz


def frd_to_flu(vx: float, vy: float, yaw_rate: float) -> tuple[float, float, float]:
    """Body FRD twist (m/s forward, m/s right, rad/s CW) -> FLU (m/s forward, m/s left, rad/s
    CCW)."""
    return vx, -vy, -yaw_rate


# --------------------------------------------------------------------------- protocol constants

# SET_POSITION_TARGET_LOCAL_NED type_mask bits (a set bit means "ignore this field").
MASK_X, MASK_Y, MASK_Z = 1, 2, 4
MASK_VX, MASK_VY, MASK_VZ = 8, 16, 32
MASK_AX, MASK_AY, MASK_AZ = 64, 128, 256
MASK_FORCE = 512
MASK_YAW = 1024
MASK_YAW_RATE = 2048
MASK_POS = MASK_X | MASK_Y | MASK_Z
MASK_VEL = MASK_VX | MASK_VY | MASK_VZ
MASK_ACC = MASK_AX | MASK_AY | MASK_AZ
# Velocity + yaw rate: position, acceleration and yaw ignored. No velocity bit may be set:
# ArduRover treats any set velocity bit as "ignore the whole velocity". For ArduRover in
# BODY_NED this is "signed forward speed + turn rate"; vy and vz are sent as 0.
MASK_VELOCITY_YAW_RATE = MASK_POS | MASK_ACC | MASK_YAW
# Velocity only (ArduRover: speed + heading from the velocity vector).
MASK_VELOCITY_ONLY = MASK_POS | MASK_ACC | MASK_YAW | MASK_YAW_RATE

FRAME_LOCAL_NED = 1
FRAME_BODY_NED = 8
FRAME_BODY_OFFSET_NED = 9
FRAME_BODY_FRD = 12

AUTOPILOT_ARDUPILOT = 3  # MAV_AUTOPILOT_ARDUPILOTMEGA
AUTOPILOT_PX4 = 12  # MAV_AUTOPILOT_PX4
AUTOPILOT_INVALID = 8
TYPE_GCS = 6
TYPE_GROUND_ROVER = 10

MODE_FLAG_CUSTOM = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
MODE_FLAG_GUIDED = 8
MODE_FLAG_ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED

# ArduRover custom modes.
ROVER_MANUAL = 0
ROVER_HOLD = 4
ROVER_GUIDED = 15
ROVER_MODES = {0: "MANUAL", 1: "ACRO", 3: "STEERING", 4: "HOLD", 5: "LOITER", 10: "AUTO",
               11: "RTL", 12: "SMART_RTL", 15: "GUIDED"}  # fmt: skip

# PX4 custom mode = main_mode << 16 | sub_mode << 24.
PX4_MAIN_MANUAL = 1
PX4_MAIN_AUTO = 4
PX4_MAIN_OFFBOARD = 6
PX4_SUB_AUTO_LOITER = 3
PX4_MAIN_NAMES = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 4: "AUTO", 5: "ACRO", 6: "OFFBOARD",
                  7: "STABILIZED"}  # fmt: skip


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4's HEARTBEAT custom_mode for a main mode and sub mode."""
    return (main_mode << 16) | (sub_mode << 24)


def px4_main_mode(custom_mode: int) -> int:
    """The main mode of a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF


PX4_OFFBOARD = px4_custom_mode(PX4_MAIN_OFFBOARD)
PX4_HOLD = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER)
PX4_MANUAL = px4_custom_mode(PX4_MAIN_MANUAL)


def mode_name(profile: str, custom_mode: int) -> str:
    """Human-readable mode name of a HEARTBEAT custom_mode for a profile."""
    if profile == "px4":
        if custom_mode == PX4_HOLD:
            return "HOLD"
        return PX4_MAIN_NAMES.get(px4_main_mode(custom_mode), f"mode {custom_mode}")
    return ROVER_MODES.get(custom_mode, f"mode {custom_mode}")


# Commands (MAV_CMD_*) and results (MAV_RESULT_*).
CMD_DO_SET_MODE = 176
CMD_COMPONENT_ARM_DISARM = 400
CMD_SET_MESSAGE_INTERVAL = 511
RESULT_ACCEPTED = 0
RESULT_TEMPORARILY_REJECTED = 1
RESULT_DENIED = 2
RESULT_UNSUPPORTED = 3
RESULT_FAILED = 4
RESULT_NAMES = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED",
                4: "FAILED", 5: "IN_PROGRESS", 6: "CANCELLED"}  # fmt: skip

# Message ids.
MSG_HEARTBEAT = 0
MSG_ATTITUDE = 30
MSG_LOCAL_POSITION_NED = 32

# Parameters (PARAM_REQUEST_READ / PARAM_VALUE).
PARAM_TYPE_REAL32 = 9  # MAV_PARAM_TYPE_REAL32
PX4_OFFBOARD_LOSS_PARAM = "COM_OF_LOSS_T"  # s PX4 keeps the last setpoint without a stream

# ArduRover failsafe parameters read on connect (Rover/Parameters.cpp, Rover/failsafe.cpp,
# Rover/mode_guided.cpp of ArduPilot; see drivers/mavlink/failsafe.py).
ROVER_FS_GCS_ENABLE = "FS_GCS_ENABLE"  # 0 disabled (default), 1 enabled, 2 continue a mission
ROVER_FS_TIMEOUT = "FS_TIMEOUT"  # s a failsafe condition lasts before FS_ACTION (default 1.5)
ROVER_FS_ACTION = "FS_ACTION"  # 0 nothing, 1 RTL, 2 Hold, 3 SmartRTL or RTL, 4 SmartRTL or Hold
ROVER_FS_GCS_TIMEOUT = "FS_GCS_TIMEOUT"  # s without a GCS heartbeat: the condition (newer fw)
ROVER_GUID_TIMEOUT = "GUID_TIMEOUT"  # s GUIDED keeps a speed/turn-rate target (newer fw)
ROVER_FS_ACTIONS = {0: "nothing", 1: "RTL", 2: "Hold", 3: "SmartRTL or RTL",
                    4: "SmartRTL or Hold"}  # fmt: skip
ROVER_FS_ACTION_HOLD = 2
ROVER_RTL = 11
ROVER_SMART_RTL = 12
ROVER_GCS_LOST_FIXED = 2.0  # s: firmware without FS_GCS_TIMEOUT starts the condition here
ROVER_GUIDED_TIMEOUT_FIXED = 3.0  # s: firmware without GUID_TIMEOUT ("target not received")
