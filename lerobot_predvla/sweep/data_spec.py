"""The `data` entries of a sweep file: how `predvla sweep` makes a suite's dataset, and the checks of those entries
(a front end shared by several suites included)."""

from dataclasses import dataclass
from pathlib import Path

from lerobot_predvla.columns import SUITES
from lerobot_predvla.data.conversion import IMAGE_STORAGES
from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN, HALF_TURN_RULES
from lerobot_predvla.sims.libero.expert.teleop import DEFAULT_STYLE, STYLES

# The settings of a front-end fit (the `predvla fit-frontend` flags a data entry sets): one per front-end folder.
FIT_SETTINGS = ("vision_weights", "language_from", "frame_stride")


@dataclass
class DataSpec:
    """How `predvla sweep` makes a suite's dataset before training: expert demonstrations (`predvla demos`), the
    front end (`predvla fit-frontend`) and the conversion (`predvla convert`) into the suite's `datasets` root.
    Each stage is skipped when its output exists (demonstrations task by task), so a killed run resumes.

    Args:
        hdf5: Root of the demonstrations (`<hdf5>/<suite>/*_demo.hdf5`).
        frontend: Directory of the fitted front-end artefact.
        frontend_from: Suites whose demonstrations this front end is fitted on jointly (one `predvla fit-frontend`
            on all their frames, as the paper fits its PCA bases on all four suites, Section 4.1), e.g.
            `[libero_spatial, libero_object, libero_goal, libero_10]`; default: this suite alone. Each listed suite
            needs its own `data` entry naming the same `frontend` folder, the same list and the same fit settings
            (`vision_weights`, `language_from`, `frame_stride`): the data stage makes every listed suite's
            demonstrations, fits the front end once, then converts each suite with it.
        per_task: Successful expert demonstrations per task (the paper's datasets have 50).
        tasks: Task ids (default: every task of the suite).
        render_interval: Render the cameras every k-th step (4 = PredVLA's visual refresh).
        demo_seed: Seed of the randomised resets of the demonstrations.
        init_noise: Std (rad) of the noise on the arm's initial joint angles of the demonstrations
            (`predvla demos --init-noise`; 0: LIBERO ControlEnv's fixed start, 0.02: the official init states').
        half_turn: Which of a finger direction and its half turn the expert grasps with (`predvla demos
            --half-turn`): 'nearest' (the current fingers') or 'wrist_centre' (the wrist joint nearer the middle of
            its range: one wrist branch per task also with init_noise).
        hold_steps: Idle steps (arm still, gripper open) recorded after each demonstration's success (`predvla demos
            --hold-steps`; 0: episodes end at success, as LIBERO's).
        style: Who executes the expert's plan (`predvla demos --style`): 'scripted' (every earlier dataset) or
            'teleop' (the teleoperator model, sims/libero/expert/teleop.py).
        diversity: With style 'teleop': how strongly the teleoperator perturbs the plan (`--diversity`; 0: the script's
            actions, 1: the committed setting).
        placement_spread: Std (cm, per axis) of a seeded x, y shift of every movable object after each reset
            (`predvla demos --placement-spread-cm`; 0: LIBERO's placements).
        vision_weights: ResNet18 weights of the front end ('imagenet', a .pth file, or 'random': the offline
            substitute, printed as such).
        language_from: Instructions of the language PCA: 'libero' (all 40 of the task list, Section 4.1) or 'demos'.
        frame_stride: Fit the visual PCA on every n-th frame.
        workers: `predvla demos` processes run at once (one per CPU core), each on every `workers`-th missing task
            (logs `seed0.demos.tasks<k>.log`). The demonstrations are the same for any value: an episode's seed
            depends only on `demo_seed`, its task and its attempt.
        oracle: Convert with the oracle front end (`predvla convert --oracle`, a diagnostic: the simulator's object
            poses relative to the gripper instead of the cameras' features; docs/frontend.md). False by default.
        image_storage: The converted dataset's camera frames (`predvla convert --image-storage`): 'video' (default),
            'png', or 'none': the cached features only, which is all training reads (the same columns and values
            as the `features-only` copy of a dataset with frames), without encoding the frames as video, the
            longest part of a conversion. With 'none', `datasets.<suite>.root` is the training dataset itself.
        frontend_threads: Torch threads of the image encoder in the front-end fit and the conversion
            (`--threads`), which run after the demonstrations, alone: the cores the demonstrations used. The
            features are the same for any count.
    """

    hdf5: str
    frontend: str
    frontend_from: list[str] | None = None
    per_task: int = 50
    tasks: list[int] | None = None
    render_interval: int = 4
    demo_seed: int = 0
    init_noise: float = 0.0
    half_turn: str = DEFAULT_HALF_TURN
    hold_steps: int = 0
    style: str = DEFAULT_STYLE
    diversity: float = 1.0
    placement_spread: float = 0.0
    vision_weights: str = "imagenet"
    language_from: str = "libero"
    frame_stride: int = 4
    workers: int = 1
    oracle: bool = False
    image_storage: str = "video"
    frontend_threads: int = 1


def fitted_suites(data: dict[str, DataSpec], suite: str) -> list[str]:
    """The suites whose demonstrations `suite`'s front end is fitted on: its `frontend_from`, or itself."""
    return list(data[suite].frontend_from or [suite])


def data_problems(data: dict[str, DataSpec], base_dir: Path) -> list[str]:
    """What is wrong with the `data` entries (empty when nothing), each naming its key; `frontend` folders are
    relative to `base_dir` (the sweep file's folder) unless absolute."""
    problems = []
    for suite, spec in data.items():
        for name, choices in (("half_turn", HALF_TURN_RULES), ("style", STYLES), ("image_storage", IMAGE_STORAGES)):
            if getattr(spec, name) not in choices:
                problems.append(f"data.{suite}.{name} must be one of {choices}, got {getattr(spec, name)!r}.")
        for name, least in (("hold_steps", 0), ("diversity", 0), ("placement_spread", 0), ("workers", 1),
                            ("frontend_threads", 1)):
            if getattr(spec, name) < least:
                problems.append(f"data.{suite}.{name} must be >= {least}, got {getattr(spec, name)}.")
        if spec.frontend_from is not None:
            problems += frontend_from_problems(data, suite)
    if problems:
        return problems
    # One front-end folder is fitted once: every suite naming it must agree on what it is fitted on and how.
    by_folder: dict[Path, list[str]] = {}
    for suite, spec in data.items():
        by_folder.setdefault((base_dir / spec.frontend).resolve(), []).append(suite)
    for folder, suites in by_folder.items():
        first = suites[0]
        fitted = fitted_suites(data, first)
        if sorted(suites) != sorted(fitted) or any(fitted_suites(data, s) != fitted for s in suites):
            fits = {s: fitted_suites(data, s) for s in suites}
            problems.append(
                f"data.<suite>.frontend {folder} is named by {suites}, fitted on {fits}: a front end shared by "
                "several suites is fitted on all of them; give each of them `frontend_from` listing exactly the "
                "suites naming that folder, in one order."
            )
            continue
        for name in FIT_SETTINGS:
            values = {s: getattr(data[s], name) for s in suites}
            if len(set(values.values())) > 1:
                problems.append(f"data.<suite>.{name} differs between the suites of the shared front end {folder}: "
                                f"{values}; one fit has one value.")
    return problems


def frontend_from_problems(data: dict[str, DataSpec], suite: str) -> list[str]:
    """What is wrong with `data.<suite>.frontend_from` itself."""
    listed = data[suite].frontend_from
    key = f"data.{suite}.frontend_from"
    if not isinstance(listed, list) or not listed or not all(isinstance(s, str) for s in listed):
        return [f"{key} must be a non-empty list of suites, got {listed!r}."]
    problems = []
    unknown = sorted(set(listed) - set(SUITES))
    if unknown:
        problems.append(f"{key}: unknown suites {unknown}; use {SUITES}.")
    if len(set(listed)) != len(listed):
        problems.append(f"{key} names a suite more than once: {listed}.")
    if suite not in listed:
        problems.append(f"{key} must include {suite} itself (its front end is fitted on its own demonstrations too).")
    without = [s for s in listed if s not in data and s in SUITES]
    if without:
        problems.append(f"{key} lists {without}, which have no `data` entry (how their demonstrations are made).")
    return problems
