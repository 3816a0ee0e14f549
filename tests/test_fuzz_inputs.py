"""The input fuzzer (``scripts/fuzz_inputs.py``) at 100 cases with a fixed seed: every case of
every kind is refused in one line or is valid (one valid case is also simulated at tiny N);
no traceback, no message over several lines, no hang. The 1,000-case run is the script's."""

from __future__ import annotations

from collections import Counter

from helpers import load_script


def test_a_hundred_fuzzed_inputs_are_refused_in_one_line_or_run() -> None:
    fz = load_script("fuzz_inputs")
    out = fz.fuzz(100, seed_value=0, simulate=1, limit_s=120.0)
    bad = [f"{o.result} [{o.case.kind}] {o.case.args or o.case.data!r}: {o.detail}" for o in out if o.result in fz.BAD]
    assert not bad, "\n\n".join(bad)
    counts = Counter(o.result for o in out)
    kinds = Counter(o.case.kind for o in out)
    assert len(out) == 100 and set(kinds) == set(fz.KINDS), kinds
    assert counts["refused"] > 50 and counts["simulated"] == 1, counts
