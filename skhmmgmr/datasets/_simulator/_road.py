"""Pseudo-random highway sections (thesis Appendix B.1, Table B.1).

A section is a concatenation of straight elements and circular arcs. Element directions (left,
right, straight), radii and angles are drawn from shuffled balanced pools so that, within a
section, they are distributed as uniformly as possible. The step curvature profile is smoothed by
a moving average of length :data:`CLOTHOID_LENGTH`, which turns every curvature step into a linear
curvature ramp (a clothoid) centred on the element boundary and keeps the heading change of every
element.
"""

import math

import numpy as np

# Table B.1: radii [m] of the curved elements per setting (100 m grid).
SETTINGS = {
    1: ("S", tuple(range(300, 601, 100))),
    2: ("M", tuple(range(600, 901, 100))),
    3: ("L", tuple(range(900, 1201, 100))),
    4: ("SM", tuple(range(300, 901, 100))),
    5: ("ML", tuple(range(600, 1201, 100))),
    6: ("SL", tuple(range(300, 601, 100)) + tuple(range(900, 1201, 100))),
    7: ("SML", tuple(range(300, 1201, 100))),
}
# Stress scenario of the thesis outlook (Appendix E.4): corners sharper than the data set's.
SHARP_CORNER_RADII = tuple(range(175, 301, 25))
ANGLES = (10, 15, 20)  # [deg]
STRAIGHT_LENGTHS = tuple(range(25, 201, 25))  # [m]
DIRECTIONS = ("straight", "left", "right")
CLOTHOID_LENGTH = 50.0  # [m] length of the linear curvature ramps
RUN_IN_LENGTH = 100.0  # [m] straight before the first element, the car starts on it
GRID_STEP = 0.25  # [m] arc-length step of the tabulated road
LANE_WIDTH = 3.5  # [m]
N_LANES = 3
# Stress scenario "wide_lane" (Appendix E.4): one 5 m lane, straights alternating with
# sinusoidal segments y = A sin(2 pi x / L) of amplitude A whose tightest radius is R.
WIDE_LANE_WIDTH = 5.0  # [m]
WIDE_LANE_STRAIGHTS = tuple(range(300, 801, 100))  # [m]
WIDE_LANE_AMPLITUDES = (1.0, 2.0, 3.0, 4.0)  # [m]
WIDE_LANE_RADII = (300, 400, 500, 600)  # [m] tightest radius of a sinusoidal segment
WIDE_LANE_PERIODS = (1, 2, 3)  # full periods per sinusoidal segment


class _BalancedPool:
    """Draw from ``values`` in shuffled rounds, so counts never differ by more than one."""

    def __init__(self, values, rng):
        self.values = list(values)
        self.rng = rng
        self.pending = []

    def draw(self):
        if not self.pending:
            self.pending = [self.values[i] for i in self.rng.permutation(len(self.values))]
        return self.pending.pop()


class Road:
    """A tabulated highway section: element list and curvature, heading on an arc-length grid.

    Attributes
    ----------
    elements : list of dict
        One dict per element with keys ``kind`` ("straight" or "arc"), ``direction``
        ("straight", "left", "right"), ``radius`` [m] (None for straights), ``angle`` [deg]
        (None for straights), ``length`` [m] and ``start`` [m] (arc length at its start).
    s : ndarray
        Arc-length grid [m], step :data:`GRID_STEP`.
    curvature : ndarray
        Smoothed centreline curvature [1/m] on ``s``, positive to the left.
    heading : ndarray
        Centreline heading [rad] on ``s``, starting at 0.
    """

    def __init__(self, elements, curvature):
        self.elements = elements
        self.curvature = curvature
        self.lane_width = LANE_WIDTH
        self.manoeuvres = []  # (start, stop, label), see manoeuvre_offsets
        self.s = np.arange(curvature.size) * GRID_STEP
        # Trapezoidal integrals: heading, then the integral of the heading (for lateral offsets).
        self.heading = _cumulative_trapezoid(curvature, GRID_STEP)
        self._heading_integral = _cumulative_trapezoid(self.heading, GRID_STEP)

    @property
    def length(self):
        """Tabulated length [m]."""
        return float(self.s[-1])

    def at(self, values, s):
        """Linearly interpolate a tabulated quantity at arc lengths ``s`` (clipped to the road)."""
        return np.interp(s, self.s, values)

    def lateral_offset(self, s, distance):
        """Lateral position [m] of the centreline ``distance`` ahead, in the frame tangent at ``s``.

        Small-angle form ``int_0^d (psi(s + x) - psi(s)) dx``; positive to the left.
        """
        s = np.asarray(s, dtype=float)
        ahead = self.at(self._heading_integral, s + distance)
        here = self.at(self._heading_integral, s)
        return ahead - here - distance * self.at(self.heading, s)

    def xy(self):
        """Centreline coordinates [m] on the grid (for plots)."""
        x = _cumulative_trapezoid(np.cos(self.heading), GRID_STEP)
        y = _cumulative_trapezoid(np.sin(self.heading), GRID_STEP)
        return x, y


def _cumulative_trapezoid(values, step):
    out = np.empty_like(values, dtype=float)
    out[0] = 0.0
    np.cumsum(0.5 * step * (values[1:] + values[:-1]), out=out[1:])
    return out


def radii_of(setting, scenario="highway"):
    """Radii [m] of the curved elements for a setting (Table B.1) or a stress scenario."""
    if scenario == "sharp_corners":
        return SHARP_CORNER_RADII
    return SETTINGS[setting][1]


def draw_elements(length, radii, rng):
    """Draw road elements until their total length reaches ``length`` [m].

    Directions (straight counted as a direction), radii, angles and straight lengths each come
    from their own balanced pool.
    """
    directions = _BalancedPool(DIRECTIONS, rng)
    radius_pool = _BalancedPool(radii, rng)
    angle_pool = _BalancedPool(ANGLES, rng)
    straight_pool = _BalancedPool(STRAIGHT_LENGTHS, rng)
    elements = []
    start = RUN_IN_LENGTH
    while start < length:
        direction = directions.draw()
        if direction == "straight":
            element = dict(kind="straight", direction=direction, radius=None, angle=None)
            element["length"] = float(straight_pool.draw())
        else:
            radius, angle = radius_pool.draw(), angle_pool.draw()
            element = dict(kind="arc", direction=direction, radius=radius, angle=angle)
            element["length"] = radius * angle * math.pi / 180.0
        element["start"] = start
        elements.append(element)
        start += element["length"]
    return elements


def step_curvature(elements, n_grid):
    """Piecewise-constant curvature [1/m] of the elements on the arc-length grid."""
    s = np.arange(n_grid) * GRID_STEP
    curvature = np.zeros(n_grid)
    for element in elements:
        if element["kind"] != "arc":
            continue
        sign = 1.0 if element["direction"] == "left" else -1.0
        mask = (s >= element["start"]) & (s < element["start"] + element["length"])
        curvature[mask] = sign / element["radius"]
    return curvature


def smooth_curvature(curvature, transition_length=CLOTHOID_LENGTH):
    """Moving average over ``transition_length``: curvature steps become linear ramps."""
    width = max(1, int(round(transition_length / GRID_STEP)))
    if width % 2 == 0:
        width += 1
    padded = np.pad(curvature, width // 2, mode="edge")
    window = np.cumsum(np.concatenate(([0.0], padded)))
    return (window[width:] - window[:-width]) / width


def make_road(length, *, setting=7, scenario="highway", random_state=None):
    """Generate a pseudo-random highway section of at least ``length`` metres.

    Parameters
    ----------
    length : float
        Minimum length [m] after the run-in straight.
    setting : int, default=7
        Radius setting of Table B.1 (1 to 7).
    scenario : str, default="highway"
        "sharp_corners" replaces the setting's radii by 175-300 m (25 m grid); "wide_lane" is one
        5 m lane of straights (300-800 m) alternating with 1 to 3 periods of sinusoidal
        segments of amplitude 1-4 m and tightest radius 300-600 m (the setting is not used);
        any other scenario uses the setting.
    random_state : numpy.random.RandomState
        Source of randomness.

    Returns
    -------
    road : Road
    """
    rng = random_state
    if scenario == "wide_lane":
        elements = draw_wide_lane_elements(RUN_IN_LENGTH + length, rng)
    else:
        elements = draw_elements(RUN_IN_LENGTH + length, radii_of(setting, scenario), rng)
    end = elements[-1]["start"] + elements[-1]["length"]
    n_grid = int(math.ceil(end / GRID_STEP)) + 1
    if scenario == "wide_lane":
        road = Road(elements, sine_curvature(elements, n_grid))
        road.lane_width = WIDE_LANE_WIDTH
        return road
    curvature = smooth_curvature(step_curvature(elements, n_grid))
    return Road(elements, curvature)


def draw_wide_lane_elements(length, rng):
    """Straights alternating with sinusoidal segments until ``length`` [m] (Appendix E.4's
    wide-lane road): each segment ``periods`` full periods of ``y = A sin(2 pi x / L)``, with
    ``L = 2 pi sqrt(A R)`` so that its tightest radius is ``R``."""
    straights = _BalancedPool(WIDE_LANE_STRAIGHTS, rng)
    amplitudes = _BalancedPool(WIDE_LANE_AMPLITUDES, rng)
    radii = _BalancedPool(WIDE_LANE_RADII, rng)
    periods = _BalancedPool(WIDE_LANE_PERIODS, rng)
    elements, start = [], RUN_IN_LENGTH
    while start < length:
        straight = dict(kind="straight", direction="straight", radius=None, angle=None)
        straight.update(length=float(straights.draw()), start=start)
        elements.append(straight)
        start += straight["length"]
        amplitude, radius = float(amplitudes.draw()), float(radii.draw())
        wavelength = 2.0 * math.pi * math.sqrt(amplitude * radius)
        sine = dict(kind="sine", direction="both", radius=radius, angle=None)
        sine.update(amplitude=amplitude, wavelength=wavelength, start=start)
        sine["length"] = wavelength * periods.draw()
        elements.append(sine)
        start += sine["length"]
    return elements


def sine_curvature(elements, n_grid):
    """Curvature [1/m] of the sinusoidal segments (``-A (2 pi / L)^2 sin(2 pi x / L)``, small
    angles), zero on the straights."""
    s = np.arange(n_grid) * GRID_STEP
    curvature = np.zeros(n_grid)
    for element in elements:
        if element["kind"] != "sine":
            continue
        x = s - element["start"]
        inside = (x >= 0.0) & (x < element["length"])
        k = 2.0 * math.pi / element["wavelength"]
        curvature[inside] = -element["amplitude"] * k * k * np.sin(k * x[inside])
    return curvature


def manoeuvre_offsets(road, scenario, rng):
    """Lateral target offset [m] of the driver along the road, for the manoeuvre scenarios.

    "lane_change" moves to the left or right lane (3.5 m) every 300-800 m, with a half-cosine
    transition over 100-150 m, and back. "evasive" inserts sudden double lane changes of 2.5-3.5 m
    over 30-40 m every 300-600 m (an obstacle in the lane). Other scenarios keep the lane centre.
    The manoeuvres are in ``road.manoeuvres``: ``(start, stop, label)`` arc lengths [m] and one
    of :data:`~skhmmgmr._core._schema.MANOEUVRES` (a lane change to the left lane and the one
    back from the right lane are both ``"lane_change_left"``).
    """
    offset = np.zeros_like(road.s)
    road.manoeuvres = []
    if scenario not in ("lane_change", "evasive"):
        return offset
    s_now, lane = RUN_IN_LENGTH + 200.0, 0.0
    while s_now < road.length:
        if scenario == "lane_change":
            target = 0.0 if lane != 0.0 else LANE_WIDTH * rng.choice((-1.0, 1.0))
            ramp = rng.uniform(100.0, 150.0)
            _add_ramp(offset, road.s, s_now, ramp, target - lane)
            side = "left" if target > lane else "right"
            road.manoeuvres.append((s_now, s_now + ramp, f"lane_change_{side}"))
            lane = target
            s_now += ramp + rng.uniform(300.0, 800.0)
        else:
            shift = rng.uniform(2.5, 3.5) * rng.choice((-1.0, 1.0))
            ramp, hold = rng.uniform(30.0, 40.0), rng.uniform(15.0, 30.0)
            _add_ramp(offset, road.s, s_now, ramp, shift)
            _add_ramp(offset, road.s, s_now + ramp + hold, ramp, -shift)
            road.manoeuvres.append((s_now, s_now + 2 * ramp + hold, "evasive"))
            s_now += 2 * ramp + hold + rng.uniform(300.0, 600.0)
    return offset


def manoeuvre_of(road, s):
    """The manoeuvre label of every arc length ``s`` (``"lane_keeping"`` outside them)."""
    labels = np.full(len(s), "lane_keeping", dtype=object)
    for start, stop, label in road.manoeuvres:
        labels[(s >= start) & (s < stop)] = label
    return labels


def _add_ramp(offset, s, start, length, height):
    x = np.clip((s - start) / length, 0.0, 1.0)
    offset += height * 0.5 * (1.0 - np.cos(math.pi * x))
