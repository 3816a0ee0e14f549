"""The paper's figures (Figs. 2, 3 and 4 of the seed paper) from run directories, as PNG + CSV.

Modules (import from them; this package file only describes them):

* ``common``  matplotlib set-up (Agg backend, no display), colours, the top-down world drawing
              (regions, tables with their padding, objects, robot start) and the CSV writer;
* ``fig2``    sampled plans of chosen CE iterations on the ground plane: base trajectories
              (orange tones, darker for successful plans), the sampled parameters as crosses, the
              iteration's best plan (base cyan solid, end effector cyan dashed);
* ``fig3``    each parameter's sampling distribution per iteration as 2-sigma ellipses;
* ``fig4``    best sampled cost per iteration and share of successful samples, mean over runs
              with a +-1 sigma band;
* ``fig_validation``  a run's validated candidates: nominal cost against success share with the
              95 % Wilson interval, the returned one highlighted, ``min_success`` dashed (not a
              figure of the paper; ``result.json``'s ``validation`` block);
* ``launch``  the seed runs behind Fig. 4 (``python -m realize`` subprocesses, resumed when
              interrupted, kept when done).

Each figure writes the PNG and a CSV with exactly the numbers plotted; ``scripts/fig2.py``,
``scripts/fig3.py``, ``scripts/fig4.py`` and ``scripts/fig_validation.py`` are the command-line
entry points. Every file is read
through ``realize.run_dir.directory.RunDir`` (formats documented in ``realize.run_dir``):
``result.json``'s series, ``history.npz``'s per-iteration samples and distributions (iteration
``i`` sampled from ``mean[i-1]``/``std[i-1]``; iteration 0, uniform, is shown with the moments of
``Z_000``; a mixture's heaviest mode), ``scene.json`` (else the run's config) and
``trajectories_iter{k}.npz`` (non-finite samples are forward-filled when drawn).
What it doesn't: simulate, or make up data: every figure reads real run files.
"""
