"""The run directory: every file a ``realize`` run writes, its schema, its one reader/writer.

Modules (import from them; this package file only describes them):

* ``names``       the file names (``result.json``, ``history.npz``, ``history_c{i}.npz``,
                  ``checkpoint.json``, ``error.txt``, ``scene.json``, ``trajectories_iter{k}.npz``,
                  ``job_status.json``);
* ``jsonio``      the one JSON encoding of inf/NaN (``null``; decoded per field) and atomic writes;
* ``summaries``   ``IterationSummary`` (one CE iteration; the checkpoint's ``records``),
                  ``CandidateSummary`` (one candidate of a top-k run), ``JobStatusDoc`` (a sweep job);
* ``result_doc``  ``ResultDoc`` (``result.json``; ``HalvingDoc`` for top-k runs) and ``FailureDoc``;
* ``build``       pure builders: ``result_doc``, ``halving_doc``, ``failure_doc`` from the search's
                  state, summaries and task; ``RunInfo``;
* ``history``     ``History`` (``history.npz``); ``checkpoint``: ``Checkpoint`` (``checkpoint.json``);
* ``scene_files`` ``scene.json`` and ``trajectories_iter{k}.npz`` (the figures' inputs);
* ``directory``   ``RunDir``: reads and writes all of the above (atomically), ``BestPlan`` for replay.

What it doesn't: run a search, decide when files are written, or draw figures.
"""
