"""``scripts/bench_long_plans.py``'s tables (issue 57): the ratios to tower3 and the line through
search time against plan length, on rows whose answer is known by construction (no run)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import bench_long_plans as blp  # noqa: E402


def _row(preset: str, actions: int, search_s: float, validated: float, seed: int = 0,
         variant: str = "plain") -> dict[str, str]:
    return {"preset": preset, "variant": variant, "seed": str(seed), "actions": str(actions),
            "search_s": str(search_s), "validated": str(validated)}


def test_time_in_proportion_to_length_passes_and_reads_the_ratios(capsys) -> None:
    # 20 s per action + 10 s: tower4 / tower3 = 130 / 90, tower5 / tower3 = 170 / 90
    rows = [_row("tower3", 4, 90, 0.95), _row("tower4", 6, 130, 0.92), _row("tower5", 8, 170, 0.91)]
    assert blp.report(rows)
    out = capsys.readouterr().out
    assert "search time against plan length: 20 s per action + 10 s" in out
    assert "x tower3 1.44 [ok <= 1.6]" in out and "x tower3 1.89 [ok <= 2.2]" in out
    assert "in proportion to plan length (the most per action within 25 % of the least): yes" in out


def test_a_slow_tower_and_a_weak_plan_are_marked(capsys) -> None:
    slow = [_row("tower3", 4, 90, 0.95), _row("tower4", 6, 150, 0.95)]  # 1.67 > 1.6
    assert not blp.report(slow)
    assert "needs three presets or more" in capsys.readouterr().out  # two points always lie on a line
    weak = [_row("tower3", 4, 90, 0.95), _row("tower4", 6, 130, 0.75)]
    assert not blp.report(weak)


def test_growth_out_of_proportion_is_called_so(capsys) -> None:
    rows = [_row("seed_paper", 5, 60, 1.0), _row("tower3", 4, 90, 0.95), _row("tower4", 6, 130, 0.95),
            _row("tower5", 8, 800, 0.95)]
    blp.report(rows)
    assert "in proportion to plan length (the most per action within 25 % of the least): no" in capsys.readouterr().out


def test_the_chain_is_compared_with_tower3_searched_the_plain_way(capsys) -> None:
    rows = [_row("tower3", 4, 100, 0.95), _row("tower3", 4, 300, 0.95, variant="chain"),
            _row("tower4", 6, 150, 0.95, variant="chain")]
    blp.report(rows)
    assert "x tower3 1.50" in capsys.readouterr().out


def test_copy_steps_count_every_copy_of_every_batch_to_its_longest_plan(tmp_path: Path) -> None:
    import numpy as np
    np.savez(tmp_path / "history.npz", steps_000=np.array([10, 30, 20]), steps_001=np.array([5, 5]), Z_000=np.zeros(3))
    np.savez(tmp_path / "history_c1.npz", steps_000=np.array([7]))
    assert blp.copy_steps(tmp_path) == 3 * 30 + 2 * 5 + 1 * 7


def test_a_robust_searchs_sample_counts_one_copy_per_world(tmp_path: Path) -> None:
    import numpy as np
    np.savez(tmp_path / "history.npz", steps_000=np.array([10, 30]), world_cost_000=np.zeros((2, 4)),
             steps_001=np.array([8, 6]), world_cost_001=np.zeros((2, 4)))
    assert blp.copy_steps(tmp_path) == 2 * 4 * 30 + 2 * 4 * 8


def test_the_work_ratio_is_printed_beside_the_time_ratio(capsys) -> None:
    rows = [{**_row("tower3", 4, 100, 0.95), "copy_steps": "1000"}, {**_row("tower4", 6, 150, 0.95), "copy_steps": "1500"}]
    blp.report(rows)
    assert "x tower3 1.50 (copy steps x tower3 1.50)" in capsys.readouterr().out


def test_runs_with_other_options_keep_their_own_rows(capsys) -> None:
    """``--extra`` names the variant, so a preset searched with an option is a row of its own
    (not collapsed into the plain one), compared with tower3 as searched today."""
    lifted = blp.variant_label("plain", ["controller.place_lift=true"])
    assert lifted == "plain[controller.place_lift=true]" and blp.variant_label("plain", []) == "plain"
    assert blp.run_dir_name("tower5", lifted, 0) == "tower5-plain_controller.place_lift_true_-s0"
    assert blp.run_dir_name("tower5", blp.variant_label("plain", ["+task.goal.margin=0.01"]), 1) == \
        "tower5-plain_task.goal.margin_0.01_-s1"
    rows = [_row("tower3", 4, 100, 0.95), _row("tower5", 8, 300, 0.75), _row("tower5", 8, 200, 0.91, variant=lifted)]
    blp.report(rows)
    out = capsys.readouterr().out
    assert f"== {lifted}" in out and "x tower3 3.00" in out and "x tower3 2.00" in out


def test_a_variant_of_many_overrides_gets_a_short_name_of_its_own() -> None:
    """Six region overrides made a directory name past the file system's 255 bytes (the run
    failed on mkdir): a long name is cut and ends in a digest of the whole, one per variant."""
    def regions(v: float) -> str:
        return blp.variant_label("plain", [f"task.params.Cube{c}_{k}.polar_max={v}" for c in "BCD" for k in ("g", "on")])
    a, b = blp.run_dir_name("tower4", regions(0.2), 2), blp.run_dir_name("tower4", regions(0.1), 2)
    assert len(a) <= blp.MAX_NAME and len(b) <= blp.MAX_NAME and a != b
    assert a.startswith("tower4-plain_task.params.CubeB_g") and a.endswith("-s2")
    assert blp.run_dir_name("tower4", regions(0.2), 2) == a  # the same variant, the same directory
