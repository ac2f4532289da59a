"""``python -m study turn_prediction``: KVLCC2's turning circles predicted from HSVA's zigzags,
with their intervals, against the other basin's measurements
(:func:`study.doctor.turn_prediction.main`)."""
from study.configuration.cli import run
from study.doctor.turn_prediction import main


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run(main, "study turn_prediction")
