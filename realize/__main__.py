"""``python -m realize [overrides]``: the same as the ``realize`` console script (``realize.cli``)."""

from realize.cli import main

if __name__ == "__main__":
    main()
