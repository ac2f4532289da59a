"""``python -m study figures``: rebuild ``paper_figs/`` and its ``CLAIMS.md`` from the results table
(:func:`study.figures.main`; ``--help`` lists the options)."""
from study.configuration.cli import run
from study.figures import main


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run(main, "study figures")
