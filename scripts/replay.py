"""Replay a run's plan in one simulated copy (CPU by default) and check it reaches the goal.

Usage: python scripts/replay.py RUN_DIR [--video out.mp4] [--fps 20] [--every 2]
                                [--width 960 --height 720] [--eye X Y Z --target X Y Z | --task-camera | --overview]
                                [--backend cpu|gpu|auto] [--json] [--state-at K --state-out FILE] [--exact]
                                [--nominal]

Reads RUN_DIR/result.json (the resolved config and the plan), rebuilds the task, scene and
controllers from that config, re-simulates the plan and prints its cost next to the search's cost
of it. The plan is the one the run returns: `validation.candidates[validation.returned].z` when
the run validated its candidates (`validation.replicas=R`, `scripts/validate.py --candidates K`),
else `best_z`; --nominal replays the search's nominal `best_z` either way. The first line says
which ran. With --video it renders every --every-th control step of copy 0 into an MP4 (on CPU
through lavapipe): a camera that follows the robot and what the current action works on, the
action and control step written on every frame. With --state-at K --state-out FILE it writes the
scene state at the moment action K (0-based) begins, right after action K-1 succeeded
(realize/world/state.py), the state `realize replan_from=RUN_DIR replan.action=K
replan.state=FILE` starts from. With --exact it re-runs the shard of copies the run simulated its
best sample in (that iteration's samples from history.npz), which gives the run's cost bit for bit
on CPU; alone in one copy the cost may be a step or two off (PhysX does not keep the copies of one
scene apart bit for bit). The task is the run's own copy (result.json's config), even if its task
file has changed since.
Exit status: 0 if the replay reaches the goal, 1 if not, 2 on a bad run dir.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.validation.replay import ReplayError, replay  # noqa: E402
from realize.config import ConfigError  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--video", type=Path, default=None, help="write an MP4 of the replay here")
    ap.add_argument("--fps", type=float, default=20.0, help="video frames per second (default 20)")
    ap.add_argument("--every", type=int, default=2, help="render every k-th control step (default 2)")
    ap.add_argument("--width", type=int, default=960)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--eye", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="a fixed camera position (with --target; default: a camera that follows the robot and "
                         "what the current action works on)")
    ap.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"))
    ap.add_argument("--task-camera", action="store_true", help="use the task's own render camera pose")
    ap.add_argument("--overview", action="store_true", help="a fixed high view of the whole world from -y")
    ap.add_argument("--hold", type=float, default=1.0, help="seconds to hold the last frame")
    ap.add_argument("--backend", choices=("cpu", "gpu", "auto"), default=None,
                    help="simulator backend (default: the run's own sim.backend)")
    ap.add_argument("--json", action="store_true", help="print the report as JSON")
    ap.add_argument("--state-at", type=int, default=None, metavar="K",
                    help="capture the scene state when action K (0-based) begins")
    ap.add_argument("--state-out", type=Path, default=None, metavar="FILE", help="write that state here (JSON)")
    ap.add_argument("--exact", action="store_true",
                    help="re-run the best sample's shard (that iteration's samples): the run's cost bit for bit")
    ap.add_argument("--nominal", action="store_true",
                    help="replay the search's nominal best_z, not the plan the run's validation returned")
    args = ap.parse_args(argv)
    if args.every < 1 or args.fps <= 0 or args.width < 16 or args.height < 16:
        ap.error("--every >= 1, --fps > 0, --width/--height >= 16")
    if (args.state_at is None) != (args.state_out is None):
        ap.error("--state-at and --state-out go together")
    try:
        rep = replay(args.run_dir, args.video, fps=args.fps, every=args.every, width=args.width,
                     height=args.height, eye=args.eye, target=args.target,
                     task_camera=args.task_camera, overview=args.overview, backend=args.backend, hold_s=args.hold,
                     state_at=args.state_at, state_out=args.state_out, exact=args.exact, nominal=args.nominal)
    except (ReplayError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2))
    else:
        saved = "none" if rep.saved_cost is None else f"{rep.saved_cost:.0f}"
        print(f"plan: {rep.plan}" + (f" [{rep.candidate}]" if rep.candidate is not None else "")
              + (f": {rep.plan_note}" if rep.plan_note else ""))
        saved_name = ("result.json best_cost" if rep.candidate is None
                      else f"validation.candidates[{rep.candidate}].cost")
        if rep.matches:
            same = "identical"
        elif rep.cost_diff is None:
            same = "no saved cost"
        else:
            same = (f"differs by {rep.cost_diff:+.0f}" + ("" if rep.exact is not None else
                    " (the run simulated it beside other samples in one PhysX scene; --exact re-runs that scene)"))
        for note in rep.notes or []:
            print(f"note: {note}")
        x = rep.exact
        how = "1 copy" if x is None else (f"exact: iteration {x.iteration} row {x.row}, shard of copies "
                                          f"{x.shard_first}-{x.shard_stop - 1} with {x.rows_in_shard} samples")
        print(f"replay ({rep.backend}, {how}): {'reaches the goal' if rep.feasible else 'FAILS: ' + rep.failure}")
        print(f"cost {rep.cost:.0f}  {saved_name} {saved}  -> {same}")
        if rep.video is not None:
            v = rep.video
            print(f"wrote {v.path}: {v.frames} frames {v.width}x{v.height} @ {v.fps:g} fps = {v.seconds:.1f} s, "
                  f"{v.bytes / 1e6:.2f} MB; render {v.render_s_per_frame * 1e3:.0f} ms/frame "
                  f"(first {v.first_render_s:.1f} s)")
        if rep.state_out is not None:
            print(f"wrote {rep.state_out}: the state at the start of action {rep.state_at}")
        print(f"wall time {rep.wall_time_s:.1f} s")
    return 0 if rep.feasible else 1


if __name__ == "__main__":
    sys.exit(main())
