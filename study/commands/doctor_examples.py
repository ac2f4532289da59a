"""``python -m study doctor_examples``: the doctor's worked examples, rebuilt into
``paper_figs/doctor/`` (:func:`study.doctor.examples.main`; ``--help`` lists the options)."""
from study.configuration.cli import run
from study.doctor.examples import main


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run(main, "study doctor_examples")
