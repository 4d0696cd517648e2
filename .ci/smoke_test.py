"""Smoke test of an installed skhmmgmr (wheel or sdist), run by .ci/run outside the checkout.

Imports the package, checks its version against the one the built artefact's file name carries
(the first argument) and the installed distribution's metadata, fits and predicts on a short
simulated recording, loads the comma2k19 sample that ships as package data (with its licence)
and runs the command line's help. Exits non-zero on any failure.
"""

import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np

import skhmmgmr
from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import load_comma2k19_sample, make_lane_keeping


def check(condition, message):
    """Fail with ``message`` (an ``assert`` would vanish under ``python -O``)."""
    if not condition:
        sys.exit(f"smoke test FAILED: {message}")


def main():
    location = Path(skhmmgmr.__file__).resolve().parent
    print(f"skhmmgmr {skhmmgmr.__version__} from {location}")
    check("site-packages" in location.parts, f"not the installed package: {location}")
    expected = sys.argv[1]
    check(
        skhmmgmr.__version__ == expected == version("skhmmgmr"),
        f"version {skhmmgmr.__version__!r}, metadata {version('skhmmgmr')!r}, "
        f"the artefact's name {expected!r}",
    )

    data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
    X = data[["steering_wheel_angle", "yaw_rate"]].to_numpy()
    y = data["driver_torque"].to_numpy()
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
    y_hat = model.predict(X)
    check(y_hat.shape == y.shape, f"prediction shape {y_hat.shape}, expected {y.shape}")
    check(np.all(np.isfinite(y_hat)), "non-finite predictions")
    r2 = model.score(X, y)
    print(f"fit/predict: {X.shape[0]} rows x {X.shape[1]} features, K=2, R^2 = {r2:.3f}")
    check(r2 > 0.5, f"R^2 {r2:.3f} is not above 0.5")

    minute = load_comma2k19_sample()
    check(minute.shape == (1200, 13), f"comma2k19 sample of shape {minute.shape}, not (1200, 13)")
    licence = location / "datasets" / "data" / "comma2k19" / "LICENSE"
    check(licence.is_file() and "comma.ai" in licence.read_text(), f"no comma.ai licence {licence}")
    print(f"comma2k19 sample: {minute.shape[0]} rows, licence beside it")

    # the console script of this environment (beside its python), whatever PATH holds
    executable = Path(sys.executable).with_name("skhmmgmr")
    check(executable.is_file(), f"no skhmmgmr command in {executable.parent}")
    for command in ([str(executable), "--help"], [sys.executable, "-m", "skhmmgmr", "--help"]):
        result = subprocess.run(command, capture_output=True, text=True)
        shown = " ".join([Path(command[0]).name, *command[1:]])
        check(result.returncode == 0, f"{shown}: exit status {result.returncode}\n{result.stderr}")
        check("usage:" in result.stdout, f"{shown}: no usage line\n{result.stdout}")
        print(f"{shown}: exit status 0")
    print("smoke test passed")


if __name__ == "__main__":
    main()
