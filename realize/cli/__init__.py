"""The command line: the ``realize`` command and Hydra sweeps.

Modules, by what you look for:

* ``main``: the ``realize`` command (``python -m realize``): the command line checked, handed to
  Hydra, one run (``realize.run.one_run``) per job, a clear exit code.
* ``sweep_check``: every job of a sweep (``realize -m``) checked before the first one simulates.
* ``sweep_summary``: a sweep's ``summary.csv`` (a Hydra callback).
* ``prebuild``: the compiled fabric step, built once per machine.

What it doesn't: compose or check the config (``realize.spec``) or run a search (``realize.run``).
"""
