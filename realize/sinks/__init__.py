"""Sinks: what a run does with each finished iteration (files, recordings, the progress bar).

Modules (import from them; this package file only describes them): ``base`` (the ``Sink``
protocol, the ``Iteration`` event and ``SinkSet``, the one place a failing sink is handled),
``files`` (``CheckpointSink``: history + checkpoint, the commit point; ``ResultSink``:
``result.json``), ``rerun`` (``RerunSink``: ``.rrd`` recordings), ``trajectories``
(``TrajectorySink``: ``scene.json`` and ``trajectories_iter{k}.npz`` for the figures) and
``progress`` (``ProgressSink``: the tqdm bar).
What they don't: search or simulate (``realize.run.loop`` drives them), or define file formats
(``realize.run_dir``).
"""
