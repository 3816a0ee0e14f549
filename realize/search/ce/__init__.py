"""Cross-entropy search over plan parameters (Algorithm 1 of the paper; Botev et al. 2013).

One job per module: ``config`` (``CEConfig``, the ``ce`` config group), ``ranking`` (sample
order, elite choice, single-normal refit, kNN-robust scores), ``mixture`` (k-means and the
mixture refit), ``state`` (``CEState``, ``IterationRecord``, ``CEResult``: what is kept and
checkpointed) and ``optimizer`` (``CrossEntropyOptimizer``: ask/tell, one iteration).
Nothing here simulates, plans symbolically or writes files; the package imports nothing
itself (import the module you need).
"""
