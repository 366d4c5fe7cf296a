"""``python -m multilat``: the same command as the ``multilat`` console script."""

from multilat.cli import run

if __name__ == "__main__":
    run()
