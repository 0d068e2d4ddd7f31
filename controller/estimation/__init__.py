"""Kalman-filtered pose feedback: per-robot and object filters (filterpy EKF or UKF).

Two layers:

* **Pure filter math** (module functions): motion models with their Jacobians, process noise
  rebuilt for any ``dt``, angle-aware residuals and means, the chi-squared gate and the
  extrapolation of a mean and covariance to a later time. Arrays in, arrays out, no state.
* **A thin stateful holder**, :class:`FleetEstimator`, that keeps one filterpy filter per robot
  and one for the object, each on its own timeline (the stamp of the last measurement it
  processed), and answers queries at a control tick by extrapolating copies.

State vectors (SI units, world frame x east, y north, theta CCW in radians):

* ``omni``:   (x, y, theta, u, v, w)  - u, v are the **body-frame** velocities (forward, left)
* ``diff``:   (x, y, theta, v, w)     - v forward speed; no lateral velocity
* ``object``: (x, y, theta, vx, vy, w) - constant velocity, **world-frame** vx, vy

Robot velocities are kept in the body frame because that is where the control input lives: the
last body-frame command ``c`` sent to the robot drives the velocity states through a first-order
lag, ``dv/dt = (c - v) / command_tau``, with white acceleration noise on top (``process_accel``,
``process_yaw_accel``). Commands are kept with their time stamps, so a prediction across an
interval uses the command that was active in each part of it. Estimates report world-frame
velocities.

Object while alive: constant velocity (a random walk on the world velocity) with
``object_process_accel``. After the arrest event (``set_object_arrested(True)``) it no longer
moves by itself: it keeps the random walk, with ``object_arrested_accel`` (tighter by default: a
held object moves only as fast as the formation's slow, smooth transport commands). If the
runtime also reports the push it commands (``push_object(t, vx, vy, wz)``, world frame, e.g. the
object twist the transport planner asks of the formation), the arrested object's velocity follows
that push through the same first-order lag as a robot's (``command_tau``); a push of zero lets it
come to rest. Without push reports it stays a pure random walk. Push reports are cleared when
the object is released.

Measurement: (x, y, theta) with noise (``meas_xy``, ``meas_theta``). A measurement's own stamp is
used; one not newer than the filter's timeline is dropped and counted (``out_of_order``). Each is
predicted to its stamp, then gated by the squared Mahalanobis distance of its innovation against
the chi-squared quantile (3 dof, ``gate_probability``) computed without touching the filter;
rejected ones are counted. ``reacquire_after`` consecutive rejections that agree with each other
(each within a few noise sigmas plus what ``init_sigma_speed``/``init_sigma_yaw_rate`` allow of
the one before) re-initialise the track from the latest measurement: a robot that was really
moved, or a filter that lost it. Scattered outliers never agree, so they never re-initialise.

A rejected measurement still moves the timeline to its stamp (the filter holds the prior there,
which is a valid state); a non-finite one is rejected without touching the filter.

Latency: ``robot_estimate(now)``, ``robot_arrays(now)`` and ``object_estimate(now)`` predict
copies of the mean and covariance from the filter's timeline to ``now`` (cached per ``now``);
the filter itself stays at its last measurement. Staleness: a track with no *accepted*
measurement for more than ``stale_after`` seconds is stale. Before its first measurement a
track is stale, not initialised, and its pose is NaN (sigmas inf): never publish or plan on it.

UKF: filterpy's ``UnscentedKalmanFilter`` with ``residual_x``/``residual_z``/``x_mean_fn``/
``z_mean_fn`` set to the angle-aware functions, and its sigma points, propagation, unscented
transform and cross-covariance done as vectorised numpy (same maths as filterpy's loops, checked
against them in the tests). EKF: filterpy's ``ExtendedKalmanFilter`` with the nonlinear motion
model and its Jacobian, the Joseph-form update and a wrapped residual.

The holder logs only on changes (a track starts or stops rejecting, re-acquires, turns stale or
fresh), never per tick.
"""
