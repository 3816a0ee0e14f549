"""``python -m realize [overrides]``: the same as the ``realize`` console script (``realize.cli.main``)."""

from realize.cli.main import main

if __name__ == "__main__":
    main()
