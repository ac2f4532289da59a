from study.app import main, precheck
from study.cli import run_hydra

if __name__ == "__main__":
    run_hydra(main, "study", precheck)
