import matplotlib
import pytest

matplotlib.use("Agg")

#: The tiny demo the report tests read (``test_cli.py``, ``test_demo_report.py``): two
#: drivers, four candidate features (those the torque pipeline needs among them), K <= 2.
TINY_DEMO = ["--drivers", "defensive", "novice", "--duration", "6", "--sampling-rate", "10"]
TINY_DEMO += ["--n-top", "2", "--k-max", "2", "--trade-off-step", "50", "--n-jobs", "1"]
TINY_DEMO += ["--features", "steering_wheel_angle", "steering_wheel_velocity", "yaw_rate"]
TINY_DEMO += ["lateral_acceleration", "--quiet"]


@pytest.fixture(scope="session")
def demo_dir(tmp_path_factory):
    """The report folder of one tiny ``skhmmgmr demo``, shared by the report tests."""
    from skhmmgmr.cli import main

    output = tmp_path_factory.mktemp("demo") / "report"
    assert main(["demo", *TINY_DEMO, "--output", str(output)]) == 0
    return output
