"""``python -m realize [overrides]``: the same as the ``realize`` console script."""

from realize.app import main

if __name__ == "__main__":
    main()
