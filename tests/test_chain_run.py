"""A chain of stitched segments through the search loop, the workers and the run directory
(slow: each simulates). The seed task's golden default search (``tests/golden_runs.py``,
``seed_paper_default``, itself the two-segment chain) with ``stitch.credit`` on (with two rounds
no dropped start is ever asked for again) gives the fixture's numbers bit for bit, so credit
that drops nothing changes nothing. A four-block tower cut
after each place runs its three segments in order, each from the one before's end states, and
result.json says which batch was which and each segment's seconds. An interrupted chain run
resumes to the uninterrupted one's result."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from golden_runs import FIXTURE, GOLDEN_RUNS, KEYS
from helpers import compose_config
from realize.run.one_run import run

QUIET = ["logging.progress=false", "logging.rerun=false"]


@pytest.mark.slow
def test_two_segments_with_credit_give_the_golden_default_search(tmp_path: Path) -> None:
    out = run(compose_config(*GOLDEN_RUNS["seed_paper_default"], "stitch.credit=2", *QUIET), tmp_path)
    assert out.status == "done"
    doc = json.loads((tmp_path / "result.json").read_text())
    golden = json.loads(FIXTURE.read_text())["seed_paper_default"]
    assert {k: doc.get(k) for k in KEYS} == {k: golden[k] for k in KEYS}
    st = doc["stitched"]
    assert st["splits"] == [2] and st["credit"] == 2 and st["segment_per_iter"] == ["prefix", "prefix", "suffix", "full"]


@pytest.mark.slow
def test_a_tower_cut_after_each_place_runs_its_segments_in_order(tmp_path: Path) -> None:
    over = ["experiment=tower4", "levers=stitched", "stitch.cut=after_each_place", "stitch.credit=2",
            "ce.n_envs=8", "ce.n_elite=2", "ce.iterations=3", "stitch.pool=3", "stitch.confirm=2", "validation=off"]
    out = run(compose_config(*over, *QUIET), tmp_path)
    assert out.status == "done"
    doc = json.loads((tmp_path / "result.json").read_text())
    st = doc["stitched"]
    assert st["splits"] == [2, 4] and list(st["segments"]) == ["segment1", "segment2", "segment3"]
    seq = st["segment_per_iter"]
    assert seq[:1] == ["segment1"] and seq.count("segment1") == 3  # segment j first runs in round j
    assert set(seq) <= {"segment1", "segment2", "segment3", "full"} and seq.index("segment1") < seq.index("segment2")
    assert all(st["segment_s"][s] > 0 for s in set(seq))
    assert len(doc["n_envs_per_iter"]) == len(seq)
    for k in range(1, 4):
        if f"segment{k}" in seq:
            assert (tmp_path / f"history_c{k}.npz").is_file()


@pytest.mark.slow
def test_a_resumed_chain_run_goes_on_from_its_checkpoint(tmp_path: Path) -> None:
    """Interrupted after round 1's suffix, a chain run (the seed task, credit on, three rounds)
    resumes from its checkpoint's searches, pools (their states as SceneState JSON), verdicts and
    stitched plans, and ends as the uninterrupted run, bit for bit."""
    over = ["levers=stitched", "ce.n_envs=12", "stitch.n_prefix=8", "ce.n_elite=3", "ce.iterations=3", "seed=0",
            "stitch.credit=2", "validation=off", *QUIET]

    def stop(i: int) -> None:
        if i == 2:
            raise KeyboardInterrupt

    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert run(compose_config(*over), whole).status == "done"
    assert run(compose_config(*over), cut, after_iteration=stop).interrupted
    ckpt = json.loads((cut / "checkpoint.json").read_text())["ce_state"]
    assert ckpt["kind"] == "stitched_chain" and ckpt["phase"] == 0 and ckpt["pools"][0]["states"]
    run(compose_config("logging.progress=false", f"resume={cut}"), tmp_path / "hydra_dir")
    a, b = (json.loads((d / "result.json").read_text()) for d in (whole, cut))
    assert b["status"] == "done" and b["stitched"]["segment_per_iter"] == a["stitched"]["segment_per_iter"]
    for key in ("n_feasible_per_iter", "best_cost_per_iter", "best_cost", "best_z"):
        assert b[key] == a[key], key
