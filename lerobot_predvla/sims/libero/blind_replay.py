"""The blind-replay ceiling: one scripted-expert plan per task, replayed with no observation on other starts.

For each task the scripted expert runs once from one of the benchmark's official init states (its *source*), and the
actions it took (its *plan*) are then replayed action by action on other official init states, without looking at
anything: `set_init_state`, the settle steps every expert episode starts with (`SETTLE_STEPS` idle steps), the plan,
then idle steps (arm still, gripper open) up to the step cap. An episode succeeds when `env.check_success()` holds after
any step, and ends there (as LIBERO's evaluation episodes do). What it measures is how far a policy that never looks
can get on these starts: a lower bound, as one plan is one choice among many.

Two plans per task, both chosen before any outcome is seen:
- `state0`: the plan from official init state `--source-state` (default 0);
- `nearest_mean`: the plan from the official init state whose object placements (x, y of every movable object after
  `set_init_state`) are nearest, in Euclidean distance over all of them, to their mean over the task's official init
  states. It is replayed on the same replay states, less its own source state if that is one of them (then one
  episode fewer).

With `Settings.style` "teleop" (`predvla blind-replay --style teleop --diversity D`) the plan is the teleoperator
model's demonstration from the source state instead (`expert.teleop`, the model `predvla demos --style teleop` records
with, seeded by the source episode's seed, `seed + source`): the same plan, executed with curved paths, varying speed,
idle stretches, overshoots and regrasps.

Each plan is also replayed on its own source state: it must reproduce the expert's success there (a check that the
replay is exact). With `Settings.shift` (`predvla blind-replay --object-shift-cm`), the replays on the replay states
start with the object to pick shifted as `predvla_libero --env.object_shift_cm` shifts it in episode k on official
init state k (`object_shift`), and each task's file records per state how the shifted object settled (`shifts`);
a plan's own source state may then be one of them (shifted, it is another start).
Fixture poses (which resets jitter outside the simulator state) are drawn from numpy's generator
seeded with `seed + state` before every reset, so a given state starts alike whichever plan runs on it.

With `Settings.resets` (`predvla blind-replay --resets-seed s --episodes n [--placement-spread-cm S]`) the plans are
replayed on randomised resets instead of official init states: episode i starts where `lerobot-eval
--env.type=predvla_libero --env.init_states=false --seed=s [--env.placement_spread_cm=S]` starts episode i of the task
(`eval_resets.eval_start`: reset seed s + i, the evaluation's placement shift, its 10 settle steps), and each task's
file records per episode its reset seed and, with a spread, the evaluation's placement record (`resets`). The plans
are still recorded from official init states, and still replayed on their own source state (with the recording's
settle steps, `settle_steps`).
"""

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.env import make_env, official_init_states, task_spec
from lerobot_predvla.sims.libero.eval_resets import ResetSpec, eval_start
from lerobot_predvla.sims.libero.expert.teleop import DEFAULT_STYLE, STYLES, TELEOP, TeleopParams
from lerobot_predvla.sims.libero.object_shift import ShiftedResets, ShiftSpec
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH, SUITE_LABELS
from lerobot_predvla.sims.libero.rollout import IDLE, SETTLE_STEPS, run_episode
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text
from lerobot_predvla.utils.statistics import episode_totals, percent

PLANS = ("state0", "nearest_mean")
NEAREST_MEAN_KEY = "nearest_mean_plan"  # report.json: the second plan's numbers, beside the state-0 plan's
REPORT_JSON, REPORT_MD, FIGURE = "report.json", "report.md", "blind_replay.png"
TASKS_DIR = "tasks"
DEFAULT_OUT = Path("results/blind_replay")
DEFAULT_STATES = tuple(range(1, 21))


@dataclass(frozen=True)
class Settings:
    """What an episode depends on; a per-task result is reused only under the same settings."""

    states: tuple[int, ...] = DEFAULT_STATES
    source_state: int = 0
    cap: int = PAPER_EPISODE_LENGTH
    settle_steps: int = SETTLE_STEPS
    seed: int = 0
    half_turn: str = "nearest"
    shift: ShiftSpec = ShiftSpec()  # the object to pick moved on the replay states (`object_shift`)
    style: str = DEFAULT_STYLE  # who executes the plan: the script, or the teleoperator model (`expert.teleop`)
    diversity: float = 1.0  # the teleoperator model's diversity (`TeleopParams.at`); the script has none
    resets: ResetSpec = ResetSpec()  # replay on lerobot-eval's randomised resets instead of `states` (`eval_resets`)

    def __post_init__(self) -> None:
        if self.style not in STYLES:
            raise ValueError(f"--style must be one of {STYLES}, got {self.style!r}")
        if not self.diversity >= 0:
            raise ValueError(f"--diversity must be >= 0, got {self.diversity}")
        if self.resets.active and self.states:
            raise ValueError("--states lists official init states to replay on; with --resets-seed the replays are on "
                             "randomised resets (--episodes)")
        if self.resets.active and self.shift.active:
            raise ValueError("--object-shift-cm shifts the object from official init states; --resets-seed replays "
                             "on randomised resets: use one or the other")

    def teleop(self) -> TeleopParams | None:
        """The teleoperator model at this diversity, or None for the scripted expert."""
        return TELEOP.at(self.diversity) if self.style == "teleop" else None

    def as_dict(self) -> dict:
        # Unshifted, scripted results keep the settings they were recorded with.
        shift = {"shift": asdict(self.shift)} if self.shift.active else {}
        style = {"style": self.style, "diversity": self.diversity} if self.style != DEFAULT_STYLE else {}
        resets = {"resets": self.resets.as_dict()} if self.resets.active else {}
        return {"states": list(self.states), "source_state": self.source_state, "cap": self.cap,
                "settle_steps": self.settle_steps, "seed": self.seed, "half_turn": self.half_turn, **shift, **style,
                **resets}

    def replay_episodes(self, source: int) -> list[int]:
        """The replays of the plan from official init state `source`: the indices of the randomised-reset episodes,
        or the official init states `states` less `source` (`excluded`)."""
        if self.resets.active:
            return list(range(self.resets.episodes))
        return [s for s in self.states if s not in self.excluded(source)]

    def excluded(self, source: int) -> list[int]:
        """`source` if it is one of `states` and its start is the plan's own (not shifted): that replay is the
        own-start check, not counted."""
        return [s for s in self.states if s == source and not self.shift.active]


def style_of(settings: dict) -> dict:
    """{"style": ..., and "diversity" for the teleoperator model} of a result's settings (`Settings.as_dict`)."""
    style = settings.get("style", DEFAULT_STYLE)
    return {"style": style, **({"diversity": settings["diversity"]} if style != DEFAULT_STYLE else {})}


def starts_of(settings: dict) -> dict:
    """The set of starts of a result's settings: {"starts": "official"}, or on randomised resets
    {"starts": "resets", "resets_seed": s, "placement_spread_cm": S}."""
    resets = settings.get("resets")
    if resets is None:
        return {"starts": "official"}
    return {"starts": "resets", "resets_seed": resets["seed"], "placement_spread_cm": resets["placement_spread_cm"]}


def default_folder(style: str, resets: ResetSpec) -> Path:
    """The output folder of a report of this style on these starts unless `--out` says: one per style and set of
    starts, e.g. results/blind_replay (scripted, official init states) or
    results/blind_replay_resets3000_placed3cm_teleop (teleop, `--resets-seed 3000 --placement-spread-cm 3`)."""
    name = DEFAULT_OUT.name
    if resets.active:
        name += f"_resets{resets.seed}" + (f"_placed{resets.placement_spread_cm:g}cm" if resets.placement_spread_cm
                                           else "")
    if style != DEFAULT_STYLE:
        name += f"_{style}"
    return DEFAULT_OUT.with_name(name)


def task_path(out: Path, suite: str, task_id: int) -> Path:
    return Path(out) / TASKS_DIR / suite / f"task{task_id}.json"


def placements(env) -> np.ndarray:
    """x, y of every movable object (LIBERO's `objects_dict`, in its order), concatenated (m)."""
    inner = env.env
    return np.concatenate([inner.sim.data.body_xpos[inner.obj_body_id[name]][:2] for name in inner.objects_dict])


def nearest_mean_state(env, init_states: np.ndarray) -> dict:
    """The official init state whose object placements are nearest their mean over all `init_states` (no outcome
    is looked at: only the states' object positions after `set_init_state`)."""
    env.reset()
    rows = []
    for state in init_states:
        env.set_init_state(state)
        rows.append(placements(env))
    rows = np.asarray(rows)
    distance = np.linalg.norm(rows - rows.mean(axis=0), axis=1)
    best = int(np.argmin(distance))
    return {"state": best, "distance_m": float(distance[best]), "median_distance_m": float(np.median(distance)),
            "objects": list(env.env.objects_dict), "init_states": len(init_states)}


def _reset(env, init_state: np.ndarray, seed: int) -> None:
    np.random.seed(seed)  # fixture poses at reset come from numpy's global generator (env.random_reset)
    env.reset()
    env.set_init_state(init_state)


def record_plan(env, init_state: np.ndarray, seed: int, settings: Settings) -> dict:
    """The scripted expert (or with `settings.style` "teleop" the teleoperator model, seeded by `seed`) from
    `init_state` (`run_episode`), its actions kept as the plan."""
    assert settings.settle_steps == SETTLE_STEPS, "run_episode settles for SETTLE_STEPS"
    np.random.seed(seed)
    episode = run_episode(env, seed, settings.cap, settings.half_turn, init_state=init_state,
                          teleop=settings.teleop())
    return {"actions": episode.actions, "success": bool(episode.success), "steps": len(episode.actions),
            "note": episode.note}


def _official_start(env, init_state: np.ndarray, seed: int, settings: Settings) -> None:
    _reset(env, init_state, seed)
    for _ in range(settings.settle_steps):
        env.step(IDLE)


def replay(env, init_state: np.ndarray, actions: np.ndarray, seed: int, settings: Settings) -> int | None:
    """From `init_state` after the settle steps, `actions` then idle steps up to `settings.cap`, without observation;
    the step count at the first success, or None."""
    _official_start(env, init_state, seed, settings)
    return _play(env, actions, settings)


def start(env, init_states: np.ndarray | None, episode: int, settings: Settings) -> dict | None:
    """Put `env` where replay episode `episode` starts, its settle steps taken: with `settings.resets`, lerobot-eval's
    randomised reset of episode `episode` (`eval_start`; `init_states` unused); else official init state `episode` of
    `init_states` (fixture poses seeded with `settings.seed + episode`), with `settings.shift` moved as lerobot-eval's
    episode `episode` on it (`object_shift`). The start's record (reset seed and placement shift, or how the shifted
    object settled), or None (official, not shifted)."""
    if settings.resets.active:
        return eval_start(env, settings.resets.reset_seed(episode), settings.resets.placement_spread_cm)
    if not settings.shift.active:
        _official_start(env, init_states[episode], settings.seed + episode, settings)
        return None
    shifts = ShiftedResets(settings.shift)
    _official_start(env, shifts.shifted(env, init_states[episode], episode), settings.seed + episode, settings)
    return {k: v for k, v in shifts.settle(env).items() if k != "spec"}


def _play(env, actions: np.ndarray, settings: Settings) -> int | None:
    for t in range(settings.cap):
        env.step(actions[t] if t < len(actions) else IDLE)
        if env.check_success():
            return t + 1
    return None


def plan_replays(env, init_states: np.ndarray, source: int, settings: Settings, progress=None) -> dict:
    """The plan recorded from official init state `source` (`record_plan`, episode seed `settings.seed + source`),
    replayed on its own source state and on `settings.replay_episodes(source)` (`start`); `progress` is called after
    every episode."""
    tick = progress or (lambda: None)
    plan = record_plan(env, init_states[source], settings.seed + source, settings)
    tick()
    own = replay(env, init_states[source], plan["actions"], settings.seed + source, settings)
    tick()
    episodes = settings.replay_episodes(source)
    outcomes, records = {}, {}
    for episode in episodes:  # on official init states the episode index is the state's, as lerobot-eval's k on k
        record = start(env, init_states, episode, settings)
        outcomes[str(episode)] = _play(env, plan["actions"], settings)
        if record is not None:
            records[str(episode)] = record
        tick()
    starts = ({"reset_episodes": episodes, "resets": records} if settings.resets.active
              else {"states": episodes, **({"shifts": records} if records else {})})
    return {
        "source_state": source, "source_success": plan["success"], "source_steps": plan["steps"],
        "source_note": plan["note"], "source_replay_step": own,
        "excluded_states": settings.excluded(source),
        **starts, "success_step": outcomes,
        "successes": sum(v is not None for v in outcomes.values()), "episodes": len(outcomes),
        "plan": plan["actions"].round(6).tolist(),
    }


def check_states(suite: str, task_id: int, init_states: np.ndarray, settings: Settings) -> None:
    """ValueError unless the source state and every replay state are official init states of the task."""
    wanted = {settings.source_state, *settings.states}
    if max(wanted) >= len(init_states) or min(wanted) < 0:
        raise ValueError(f"{suite} task {task_id} has {len(init_states)} official init states (0-"
                         f"{len(init_states) - 1}); --states / --source-state ask for {sorted(wanted)}")


def run_task(suite: str, task_id: int, settings: Settings, progress=None) -> dict:
    """Both plans of one task, each replayed on `settings.states` (and on its own source state); `progress` is
    called after every episode."""
    t0 = time.time()
    spec = task_spec(suite, task_id)
    init_states = official_init_states(suite, task_id)
    check_states(suite, task_id, init_states, settings)
    env = make_env(spec)
    try:
        nearest = nearest_mean_state(env, init_states)
        sources = {"state0": settings.source_state, "nearest_mean": nearest["state"]}
        plans = {name: plan_replays(env, init_states, source, settings, progress) for name, source in sources.items()}
    finally:
        env.close()
    return {"suite": suite, "task_id": task_id, "task_name": spec.name, "language": spec.language,
            "settings": settings.as_dict(), "nearest_mean": nearest, "plans": plans,
            "seconds": round(time.time() - t0, 1)}


def episodes_per_task(settings: Settings) -> int:
    """Episodes of one task for the progress bar: per plan a recording, its own-source replay and the replays."""
    return len(PLANS) * (2 + (settings.resets.episodes if settings.resets.active else len(settings.states)))


def load_task(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


# ----- the report ---------------------------------------------------------------------------------------------
def _entry(task: dict) -> dict:
    first, second = task["plans"]["state0"], task["plans"]["nearest_mean"]

    def numbers(plan: dict) -> dict:
        return {"successes": plan["successes"], "episodes": plan["episodes"], "source_state": plan["source_state"],
                "source_success": plan["source_success"], "source_replay_success": plan["source_replay_step"]
                is not None, "plan_steps": plan["source_steps"], "excluded_states": plan["excluded_states"]}

    return {**numbers(first), "task_name": task["task_name"], "states": task["settings"]["states"],
            "cap": task["settings"]["cap"], "seconds": task["seconds"], **style_of(task["settings"]),
            **starts_of(task["settings"]), **({"reset_episodes": first["reset_episodes"]} if "resets" in first else {}),
            NEAREST_MEAN_KEY: numbers(second)}


def collect(out: Path) -> dict[str, dict[str, dict]]:
    """report.json's content: suite -> task id -> numbers of the state-0 plan, with the nearest-mean plan's under
    NEAREST_MEAN_KEY; from every per-task file under `out` (suites in SUITES order, tasks by id)."""
    report = {}
    for suite in SUITES:
        files = sorted((Path(out) / TASKS_DIR / suite).glob("task*.json"), key=lambda p: int(p.stem[4:]))
        tasks = {}
        for path in files:
            task = load_task(path)
            if task is None:
                raise ValueError(f"{path}: unreadable per-task result; delete it to run that task again")
            tasks[str(task["task_id"])] = _entry(task)
        if tasks:
            report[suite] = tasks
    return report


def shift_totals(out: Path) -> dict[str, tuple[float, int, int]]:
    """Per suite of the report at `out`: (the object shift in cm, 0 without one; successes, episodes of the plan from
    the source state), from its per-task files, whose settings name the shift."""
    found = {}
    for suite in SUITES:
        files = sorted((Path(out) / TASKS_DIR / suite).glob("task*.json"))
        tasks = [load_task(path) for path in files]
        if not tasks:
            continue
        if any(task is None for task in tasks):
            raise ValueError(f"{Path(out) / TASKS_DIR / suite}: an unreadable per-task result")
        shifts = {float((task["settings"].get("shift") or {}).get("object_cm", 0.0)) for task in tasks}
        if len(shifts) != 1:
            raise ValueError(f"{out}: the tasks of {suite} ran with different object shifts {sorted(shifts)}")
        successes, episodes = episode_totals(task["plans"]["state0"] for task in tasks)
        found[suite] = (shifts.pop(), successes, episodes)
    if not found:
        raise ValueError(f"{out}: no `predvla blind-replay` per-task results under {TASKS_DIR}/")
    return found


def totals(tasks: dict[str, dict], key: str | None = None) -> tuple[int, int]:
    """(successes, episodes) of a suite's tasks: the state-0 plan's, or with `key` (`NEAREST_MEAN_KEY`) the other's."""
    return episode_totals(t if key is None else t[key] for t in tasks.values())


def totals_with_source(tasks: dict[str, dict]) -> tuple[int, int]:
    """(successes, episodes) of the state-0 plan on its replay states and on its own start (`source_replay_success`,
    one episode per task): on official init states 1..n-1 the figure for the starts 0..n-1 an evaluation uses."""
    successes, episodes = totals(tasks)
    return successes + sum(bool(t["source_replay_success"]) for t in tasks.values()), episodes + len(tasks)


def _pct(successes: int, episodes: int) -> str:
    return f"{percent(successes, episodes):.1f}%" if episodes else "—"


def _states_text(states: list[int]) -> str:
    states = sorted(states)
    if states == list(range(states[0], states[-1] + 1)):
        return f"{states[0]}-{states[-1]}"
    return ", ".join(map(str, states))


def markdown_head(title: str, text: str, command: str) -> list[str]:
    """The opening lines of a blind-replay report: its title, what it measures, and the command that made it."""
    return [f"# {title}", "", text, "", "Reproduce:", "", "```bash", command, "```", ""]


def plan_words(entry: dict) -> str:
    """Who made the plans of a report entry (`_entry`), for the report's text."""
    if entry.get("style", DEFAULT_STYLE) == DEFAULT_STYLE:
        return "The scripted expert's plan"
    return f"The teleoperator model's demonstration (`--style {entry['style']}`, diversity {entry['diversity']:g})"


def starts_words(entry: dict) -> str:
    """The starts a report entry (`_entry`) was replayed on, for the report's text."""
    if entry.get("starts", "official") == "official":
        return f"Replay states {_states_text(entry['states'])}"
    episodes = entry["reset_episodes"]
    seeds = f"{entry['resets_seed'] + episodes[0]}-{entry['resets_seed'] + episodes[-1]}"
    spread = entry["placement_spread_cm"]
    return (f"Randomised resets: episodes {_states_text(episodes)} of `lerobot-eval --env.init_states=false "
            f"--seed={entry['resets_seed']}" + (f" --env.placement_spread_cm={spread:g}" if spread else "") +
            f"` (reset seeds {seeds})")


def source_plan_words(entry: dict) -> str:
    """The report's name for the plan from `--source-state` (`entry`: any task entry of the report)."""
    return f"plan from state {entry['source_state']}"


def markdown(report: dict, command: str, expected_tasks: dict[str, int]) -> str:
    entry = next(iter(next(iter(report.values())).values()))
    if entry.get("starts", "official") == "official":
        where = "other official init states: `set_init_state`,"
    else:
        where = ("the randomised resets `predvla_libero` starts `lerobot-eval --env.init_states=false` episodes from "
                 "(the same reset seeds, placement shifts and arm start), then")
    lines = markdown_head("One demonstration replayed blind",
             f"{plan_words(entry)} (its actions) from one official init state of each task, replayed action by "
             f"action with no observation on {where} the settle steps, the "
             "plan, then idle steps (arm still, gripper open) up to the step cap; success is LIBERO's "
             "`check_success()` after any step. Two plans per task, both chosen before any outcome: from official "
             f"init state {entry['source_state']}, and from the official init state whose object placements are "
             "nearest their mean over "
             "the task's 50 official init states (that plan is not replayed on its own source state: one episode "
             "fewer where its source is a replay state). *Own start* is each plan replayed on its source state "
             "(must succeed wherever the expert did).", command)
    for suite, tasks in report.items():
        first = next(iter(tasks.values()))
        s0, n0 = totals(tasks)
        s1, n1 = totals(tasks, NEAREST_MEAN_KEY)
        lines += [f"## {suite}", "",
                  f"{starts_words(first)}, {first['cap']}-step cap. "
                  f"{source_plan_words(first).capitalize()}: **{s0}/{n0} ({_pct(s0, n0)})**; plan from the "
                  "nearest-mean state: "
                  f"**{s1}/{n1} ({_pct(s1, n1)})**. Wall time {sum(t['seconds'] for t in tasks.values()) / 60:.0f} "
                  "min (one process, physics only).", ""]
        missing = expected_tasks.get(suite, 0) - len(tasks)
        if missing > 0:
            lines += [f"{missing} of {expected_tasks[suite]} tasks not run yet.", ""]
        lines += [f"| task | {source_plan_words(first)}: successes | its steps | expert / own start | "
                  "nearest-mean source "
                  "state | its plan: successes | its steps | expert / own start | wall time (s) | name |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for task_id, t in tasks.items():
            m = t[NEAREST_MEAN_KEY]

            def ok(row: dict) -> str:
                expert = "yes" if row["source_success"] else "**no**"
                return f"{expert} / {'yes' if row['source_replay_success'] else 'no'}"

            lines.append(f"| {task_id} | {t['successes']}/{t['episodes']} | {t['plan_steps']} | {ok(t)} | "
                         f"{m['source_state']} | {m['successes']}/{m['episodes']} | {m['plan_steps']} | {ok(m)} | "
                         f"{t['seconds']:.0f} | {t['task_name']} |")
        failed = [task_id for task_id, t in tasks.items() if not t["source_success"]
                  or not t[NEAREST_MEAN_KEY]["source_success"]]
        if failed:
            lines += ["", f"Tasks {', '.join(failed)}: the expert failed from a source state; its plan (what it did "
                      "up to the cap) is replayed all the same and counted."]
        lines.append("")
    lines += [f"![per-task success]({FIGURE})", ""]
    return "\n".join(lines)


def figure(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    suites = list(report)
    fig, axes = plt.subplots(len(suites), 1, figsize=(9, 2.6 * len(suites) + 0.6), squeeze=False)
    for ax, suite in zip(axes[:, 0], suites, strict=True):
        tasks = report[suite]
        x = np.arange(len(tasks))
        source_plan = source_plan_words(next(iter(tasks.values())))
        for offset, key, label in ((-0.2, None, source_plan), (0.2, NEAREST_MEAN_KEY,
                                                               "plan from the nearest-mean state")):
            rows = [t if key is None else t[key] for t in tasks.values()]
            ax.bar(x + offset, [100 * r["successes"] / max(r["episodes"], 1) for r in rows], width=0.4, label=label)
        s0, n0 = totals(tasks)
        s1, n1 = totals(tasks, NEAREST_MEAN_KEY)
        ax.set_title(f"{suite}: {source_plan} {_pct(s0, n0)} ({s0}/{n0}), from the nearest-mean state "
                     f"{_pct(s1, n1)} ({s1}/{n1})", fontsize=10)
        ax.set_xticks(x, list(tasks))
        ax.set_xlim(-0.6, max(len(tasks), 10) - 0.4)
        ax.set_ylim(0, 105)
        ax.set_ylabel("success (%)")
    axes[-1, 0].set_xlabel("task")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.suptitle("One demonstration replayed blind: success per task on the replay states")
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.955), ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)


def write_report(out: Path, command: str, expected_tasks: dict[str, int]) -> dict:
    """report.json, report.md and the figure from every per-task file under `out`."""
    report = collect(out)
    if not report:
        return report
    atomic_write_json(Path(out) / REPORT_JSON, report)
    atomic_write_text(Path(out) / REPORT_MD, markdown(report, command, expected_tasks))
    figure(report, Path(out) / FIGURE)
    return report


def suite_label(suite: str) -> str:
    return SUITE_LABELS.get(suite, suite)
