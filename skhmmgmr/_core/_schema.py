"""Column convention shared by every dataset of the package.

A dataset is a tidy :class:`pandas.DataFrame` with one row per sample. Rows of one recording are
contiguous and in time order. The meta columns come first, then the candidate features, then the
driver torque (the regression target), then the columns of an experiment, if any (the torque of a
perturbation experiment).
"""

RECORDING = "recording"
DRIVER = "driver"
SETTING = "setting"
SPLIT = "split"
TIME = "time"
TARGET = "driver_torque"

# What the driver is doing (simulated frames): keeping the lane or a manoeuvre of MANOEUVRES,
# and for the rows of a manoeuvre the time [s] its car crosses a lane marking (NaN if never).
MANOEUVRE = "manoeuvre"
CROSSING_TIME = "crossing_time"
MANOEUVRES = ("lane_keeping", "lane_change_left", "lane_change_right", "evasive")
META_COLUMNS = (RECORDING, DRIVER, SETTING, SPLIT, TIME, MANOEUVRE, CROSSING_TIME)
# The torque of a perturbation experiment on the steering wheel (simulated frames made with
# perturbation=; 0 where a recording had none): a label of the recording, after the target,
# which a model may read in fit and never needs as an input. EXPERIMENT_COLUMNS are the
# optional columns after the target; like the meta columns, never features.
STEERING_PERTURBATION = "steering_perturbation"
EXPERIMENT_COLUMNS = (STEERING_PERTURBATION,)
#: Units of the numeric labels.
LABEL_UNITS = {CROSSING_TIME: "s", STEERING_PERTURBATION: "Nm"}

# The 18 candidate features of the thesis (Table B.2), in its order, with SI units.
FEATURE_UNITS = {
    "steering_wheel_angle": "rad",
    "steering_wheel_velocity": "rad/s",
    "steering_wheel_acceleration": "rad/s^2",
    "lateral_velocity": "m/s",
    "lateral_acceleration": "m/s^2",
    "slip_angle": "rad",
    "yaw_rate": "rad/s",
    "yaw_acceleration": "rad/s^2",
    "roll_angle": "rad",
    "roll_velocity": "rad/s",
    "roll_acceleration": "rad/s^2",
    "lateral_deviation_0m": "m",
    "heading_deviation_0m": "rad",
    "road_curvature_0m": "1/m",
    "heading_deviation_10m": "rad",
    "road_curvature_10m": "1/m",
    "heading_deviation_30m": "rad",
    "road_curvature_30m": "1/m",
}
FEATURE_NAMES = tuple(FEATURE_UNITS)
# What the driver sees of the road ahead (the lane camera's features): a model of the driver's
# perception, which drives the simulator in closed loop where models that also read the
# steering system's and the vehicle's states learn the steering system's inverse and diverge.
PREVIEW_FEATURES = (
    "lateral_deviation_0m",
    "heading_deviation_0m",
    "road_curvature_0m",
    "heading_deviation_10m",
    "road_curvature_10m",
    "heading_deviation_30m",
    "road_curvature_30m",
)
# What a driver model reads (make_driver_model): every sensed feature but the steering wheel's
# acceleration, which the logger differentiates twice from the angle (a few samples late): at the
# wheel a model's torque would follow it, a delayed positive feedback on the wheel's inertia
# that makes the model oscillate at 20 Hz.
DRIVER_MODEL_FEATURES = tuple(
    name for name in FEATURE_NAMES if name != "steering_wheel_acceleration"
)
TARGET_UNIT = "Nm"
