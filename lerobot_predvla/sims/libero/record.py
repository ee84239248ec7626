"""Recording scripted-expert LIBERO demonstrations (`predvla demos`): roll out without rendering from randomised resets,
keep the successful episodes and render their images afterwards by replaying the saved states, into the original hdf5
layout (hdf5_layout.py).
"""

import argparse
import time

from tqdm import tqdm

from lerobot_predvla.sims.libero.env import make_env, num_tasks, official_init_states, random_reset, task_spec
from lerobot_predvla.sims.libero.expert.teleop import TELEOP
from lerobot_predvla.sims.libero.hdf5_layout import file_attrs, task_file, write_task_file
from lerobot_predvla.sims.libero.protocol import STEP_CAPS
from lerobot_predvla.sims.libero.render import replay_observations
from lerobot_predvla.sims.libero.rollout import run_episode
from lerobot_predvla.utils.versions import openblas_coretype


def episode_seed(seed: int, task_id: int, attempt: int) -> int:
    return seed * 1_000_003 + task_id * 10_007 + attempt


def style_attrs(style: str, diversity: float, placement_spread_cm: float) -> dict:
    """The file attributes that name a demonstration style and a placement spread; none for the scripted style's
    LIBERO placements, so every earlier dataset is written as before."""
    attrs = {"predvla_style": style, "predvla_diversity": diversity} if style != "scripted" else {}
    return {**attrs, **({"predvla_placement_spread_cm": placement_spread_cm} if placement_spread_cm > 0 else {})}


def record_demos(args: argparse.Namespace) -> int:
    """`predvla demos` with its parsed arguments (cli/demos.py): roll out, keep the successes, render and write them;
    prints the expert's success per task. Exit code 1 when a task kept no demonstration."""
    if args.per_task < 1:
        raise SystemExit("--per-task must be >= 1")
    if args.render_interval < 1:
        raise SystemExit("--render-interval must be >= 1")
    if args.init_noise < 0:
        raise SystemExit(f"--init-noise must be >= 0, got {args.init_noise}")
    if args.hold_steps < 0:
        raise SystemExit(f"--hold-steps must be >= 0, got {args.hold_steps}")
    if args.official_init_states and not args.no_render:
        raise SystemExit("--official-init-states only measures expert success: pass --no-render with it "
                         "(demonstrations never start from the evaluation init states)")
    if args.diversity is not None and args.style != "teleop":
        raise SystemExit(f"--diversity {args.diversity} needs --style teleop (the script has no diversity)")
    diversity = 1.0 if args.diversity is None else args.diversity
    if diversity < 0:
        raise SystemExit(f"--diversity must be >= 0, got {diversity}")
    if args.placement_spread_cm < 0:
        raise SystemExit(f"--placement-spread-cm must be >= 0, got {args.placement_spread_cm}")
    teleop = TELEOP.at(diversity) if args.style == "teleop" else None
    if args.out is None and not args.no_render:
        raise SystemExit("--out is required (or pass --no-render to only measure expert success)")
    n_tasks = num_tasks(args.suite)
    task_ids = args.tasks if args.tasks is not None else list(range(n_tasks))
    if outside := [t for t in task_ids if not 0 <= t < n_tasks]:
        raise SystemExit(f"--tasks {outside}: {args.suite} has tasks 0-{n_tasks - 1}")
    max_attempts = args.max_attempts or 3 * args.per_task
    max_steps = args.max_steps or STEP_CAPS[args.suite]
    report = []
    for task_id in task_ids:
        spec = task_spec(args.suite, task_id)
        t0 = time.time()
        env = make_env(spec, init_noise=args.init_noise)
        init_states = official_init_states(args.suite, task_id) if args.official_init_states else None
        kept, attempts, notes = [], 0, []
        with tqdm(total=args.per_task, desc=f"{args.suite}/{task_id} rollouts", unit="demo") as bar:
            while len(kept) < args.per_task and attempts < max_attempts:
                start = None if init_states is None else init_states[attempts % len(init_states)]
                episode = run_episode(env, episode_seed(args.seed, task_id, attempts), max_steps, args.half_turn,
                                      init_state=start, hold_steps=args.hold_steps, teleop=teleop,
                                      placement_spread=args.placement_spread_cm / 100)
                attempts += 1
                if episode.success:
                    kept.append(episode)
                    bar.update(1)
                else:
                    notes.append(episode.note)
                bar.set_postfix(attempts=attempts)
        env.close()
        t_roll = time.time() - t0
        demos = []
        if kept and not args.no_render:
            render_env = make_env(spec, render=True)
            random_reset(render_env, 0)
            attrs = {**file_attrs(spec, render_env, args.init_noise), "predvla_render_interval": args.render_interval,
                     "predvla_half_turn": args.half_turn, "predvla_hold_steps": args.hold_steps,
                     **style_attrs(args.style, diversity, args.placement_spread_cm)}
            for episode in tqdm(kept, desc=f"{args.suite}/{task_id} rendering", unit="demo"):
                obs = replay_observations(render_env, episode, args.render_interval)
                demos.append({**obs, "actions": episode.actions, "states": episode.states,
                              "model_file": episode.model_xml})
            render_env.close()
            path = task_file(args.out, spec)
            write_task_file(path, attrs, demos)
            tqdm.write(f"wrote {path} ({len(demos)} demos)")
        steps = sum(len(e.actions) for e in kept)
        report.append((spec, attempts, len(kept), steps, t_roll, time.time() - t0 - t_roll, notes))

    starts = "official init states" if args.official_init_states else \
        f"randomised resets, seed {args.seed}, initial joint noise {args.init_noise}"
    style = f"teleop at diversity {diversity}" if args.style == "teleop" else "scripted"
    spread = f", placements shifted by {args.placement_spread_cm} cm (std)" if args.placement_spread_cm > 0 else ""
    print(f"\nExpert success ({args.suite}, {starts}, half turn {args.half_turn}, {style}{spread}):")
    print(f"(numpy's OpenBLAS kernels: {openblas_coretype()}; the demonstrations regenerate bit for bit only under the "
          "same kernels, which OPENBLAS_CORETYPE pins)")
    print(f"{'task':>4}  {'attempts':>8}  {'successes':>9}  {'rate':>5}  {'steps/demo':>10}  "
          f"{'s/attempt':>9}  {'render s/demo':>13}  name")
    for spec, attempts, ok, steps, t_roll, t_render, _ in report:
        print(f"{spec.task_id:>4}  {attempts:>8}  {ok:>9}  {ok / max(attempts, 1):>5.0%}  "
              f"{steps / max(ok, 1):>10.0f}  {t_roll / max(attempts, 1):>9.1f}  "
              f"{t_render / max(ok, 1):>13.1f}  {spec.name}")
    failed = [(s.task_id, n) for s, *_, n in report if n]
    for task_id, notes in failed:
        print(f"task {task_id} failures: {sorted(set(notes))}")
    short = [s.task_id for s, _, ok, *_ in report if ok < args.per_task]
    if short:
        print(f"WARNING: tasks {short} have fewer than {args.per_task} demonstrations")
    return 1 if any(ok == 0 for _, _, ok, *_ in report) else 0
