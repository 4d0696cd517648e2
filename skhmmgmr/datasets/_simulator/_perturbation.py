"""The perturbation experiment: a torque on the steering wheel that the driver does not know.

In a recording of ordinary driving the steering wheel moves only as the driver turns it, so
that a regression of the driver's torque on the wheel's own state cannot tell the driver's
arms from the steering system's load (the data hold no motion of the wheel that the driver
did not cause). Neuromuscular-admittance experiments add a small torque disturbance that
the driver cannot predict: a multisine, the sum of sines at many frequencies with random
phases. Here it is a torque at the steering wheel, added to the driver's hands' torque where
the closed loop calls the steering column (:mod:`._closed_loop`): the steering system cannot
tell it from the driver's (the assist boosts it, a torsion bar carries it), and the driver
feels it only through the wheel's motion, as the arms' impedance and, after the reaction
time, the eyes respond to it. The logged ``driver_torque`` is the driver's own share, the
torque sensor's reading less the perturbation (the experiment knows what it applies); the
perturbation itself is logged as ``steering_perturbation`` [Nm].

The multisine has :data:`N_COMPONENTS` sines of equal amplitude at frequencies spaced
evenly on a log scale over :data:`BAND` (0.05-5 Hz), each rounded to a whole number of
periods over the section (so that it repeats with the section: its RMS over the logged rows
is the RMS asked for, and its spectrum holds nothing outside those frequencies), with phases
drawn uniformly. Its random stream is its own: an int ``random_state`` seeds it by
:class:`numpy.random.SeedSequence` with :data:`STREAM_KEY`, so that the road, the driver, the
noises and the sensor errors of a perturbed section are those of the unperturbed one.
"""

import math

import numpy as np

#: [Hz] The band of the multisine's frequencies.
BAND = (0.05, 5.0)
#: Sines of the multisine (fewer when the section's whole periods cannot hold as many).
N_COMPONENTS = 24
#: The spawn key that sets the perturbation's random stream apart from the section's.
STREAM_KEY = 0x5EA7


def perturbation_stream(random_state, section_rng):
    """The perturbation's own random generator.

    An int ``random_state`` seeds it through a :class:`numpy.random.SeedSequence` with
    :data:`STREAM_KEY`; ``None`` draws fresh entropy; a ``RandomState`` instance gives one
    number, drawn from ``section_rng`` (the instance itself) after the section's own draws.
    """
    if isinstance(random_state, (int, np.integer)):
        return np.random.default_rng(
            np.random.SeedSequence(int(random_state), spawn_key=(STREAM_KEY,))
        )
    if random_state is None:
        return np.random.default_rng()
    return np.random.default_rng(int(section_rng.randint(np.iinfo(np.int32).max)))


def multisine_frequencies(duration):
    """The multisine's frequencies [Hz] over a section of ``duration`` seconds: whole numbers
    of periods over it, log-evenly spread over :data:`BAND`."""
    low, high = math.ceil(BAND[0] * duration - 1e-9), math.floor(BAND[1] * duration + 1e-9)
    low = max(low, 1)
    if high < low:
        raise ValueError(
            f"perturbation needs a section of at least {1.0 / BAND[1]:g} s (one period of its "
            f"highest frequency, {BAND[1]:g} Hz); got duration={duration:g} s."
        )
    cycles = np.unique(np.round(np.geomspace(low, high, N_COMPONENTS)).astype(int))
    return cycles / duration


def multisine(rms, duration, dt, n_steps, rng):
    """The perturbation torque [Nm] at every integration step (``n_steps`` steps of ``dt``
    seconds over a section of ``duration`` seconds): a multisine of RMS ``rms``."""
    frequencies = multisine_frequencies(duration)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=len(frequencies))
    amplitude = rms * math.sqrt(2.0 / len(frequencies))
    time = np.arange(n_steps) * dt
    torque = np.zeros(n_steps)
    for frequency, phase in zip(frequencies, phases, strict=True):
        torque += np.sin(2.0 * math.pi * frequency * time + phase)
    return amplitude * torque
