"""``python -m realize [overrides]``: the same as the ``realize`` console script (``realize.app.cli``)."""

from realize.app.cli import main

if __name__ == "__main__":
    main()
