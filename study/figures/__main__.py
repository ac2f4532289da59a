from ..cli import run
from . import main

run(main, "study.figures")
