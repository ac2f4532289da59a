import sys

from study.commands import dispatch

if __name__ == "__main__":
    dispatch(sys.argv)
