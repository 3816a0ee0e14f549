"""The search over plan parameters: the ask/tell protocol and what runs over it.

Modules: ``protocol`` (``Searcher``, ``Batch``, ``EvalResult``: what the loop asks and tells),
``ce`` (the cross-entropy optimizer, Algorithm 1), ``candidates`` and ``budget`` (successive
halving over the k best symbolic plans), ``warm_start`` (a search begun from an earlier run's
final distribution), ``segments``, ``chain`` and ``chain_pool`` (a plan searched as segments
stitched together, one cut or several, with credit: the budget and names, the search, and its
pools of start states).
What it doesn't: simulate (``realize.realization``) or run the loop (``realize.run.loop``).
"""
