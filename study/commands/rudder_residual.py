"""``python -m study rudder_residual``: the residual yaw moment of KVLCC2's fit to HSVA's zigzags
against the rudder angle, per rudder-angle bin (:func:`study.doctor.rudder_residual.main`)."""
from study.configuration.cli import run
from study.doctor.rudder_residual import main


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run(main, "study rudder_residual")
