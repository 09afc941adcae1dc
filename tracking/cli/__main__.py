"""`python -m tracking.cli`: the same as the `topside` console script."""

from tracking.cli import main

if __name__ == "__main__":
    main()
