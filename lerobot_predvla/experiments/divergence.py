"""Where PredVLA's exact open loop leaves the demonstrations (`predvla divergence`, issue 61 deliverable 2).

In the simulator: each chosen demonstration's own first MuJoCo state (and its fixture poses, from the scene XML it
saved) is set, and three action sequences are run from it, physics only:

- `replay`: the demonstration's own actions (the simulator's reproducibility: the floor of every distance below);
- `open_loop`: PredVLA's exact open-loop actions (`er_iterations=0`: every posterior at its prior, so the actions
  depend on the instruction alone), unnormalised by the checkpoint's postprocessor, up to the step cap (stopped at
  success, as `lerobot-eval` does);
- `open_loop_demo_rotation`: the same open-loop actions with their three rotation commands replaced by the
  demonstration's own (zero past its end): a counterfactual, how much of the open loop's failure its orientation
  carries;
- `blind_plan`: another demonstration's actions of the same task (the next one in the file), then idle steps up to
  the cap: what one plan replayed with no observation does from this start (the blind-replay reference).

Per step each rollout's end-effector position, joint angles and gripper are compared with the demonstration's
own recorded trajectory; the demonstration's phases (approach, grasp, lift, carry/place, release) come from its
gripper command and end-effector height.

Offline (no simulator): the open loop's actions against every demonstration of the task, per step, against the
task's time-aligned mean demonstration and against the demonstrations' spread (their envelope, min to max, and how
far each lies from the mean). The checkpoint holds no training posteriors, so the rollout driven by them (the
prior chain's one-step, training-mode error) cannot be measured here.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

PHASES = ("approach", "grasp", "lift", "carry/place", "release")
SEPARATION_THRESHOLDS_M = (0.01, 0.02, 0.05, 0.10)
LIFT_RISE_M = 0.01  # the lift starts when the end effector is this far above where the gripper closed
TOP_MARGIN_M = 0.01  # the lift ends within this distance of the highest point before release
ENVELOPE_MIN_DEMOS = 0.5  # envelope and mean demonstration only where at least this fraction of demos still runs
EXIT_RUN = 3  # consecutive steps outside the envelope that count as leaving it
ENVELOPE_MARGIN = 0.02  # raw action units (actions lie in [-1, 1]): where every demo commands the same, e.g. full
# speed, the envelope has no width, and the open loop's 0.997 for their 1.0 should not count as leaving it
BLIND_IDLE_STEPS = 100  # idle steps after a blind plan, as the blind-replay measurement


@dataclass
class Demo:
    index: int
    actions: np.ndarray  # (N, 7)
    states: np.ndarray  # (N, S)
    ee_pos: np.ndarray  # (N, 3)
    ee_ori: np.ndarray  # (N, 3) axis-angle
    joints: np.ndarray  # (N, 7)
    gripper: np.ndarray  # (N, 2) finger joint positions
    model_xml: str


def demo_file(hdf5_root: Path, suite: str, task_name: str) -> Path:
    return Path(hdf5_root) / suite / f"{task_name}_demo.hdf5"


def read_demos(path: Path, indices: list[int]) -> list[Demo]:
    import h5py

    out = []
    with h5py.File(path, "r") as f:
        for i in indices:
            g = f[f"data/demo_{i}"]
            out.append(Demo(i, g["actions"][()], g["states"][()], g["obs/ee_pos"][()], g["obs/ee_ori"][()],
                            g["obs/joint_states"][()],
                            g["obs/gripper_states"][()], str(g.attrs["model_file"])))
    return out


def read_all_actions(path: Path) -> list[np.ndarray]:
    import h5py

    with h5py.File(path, "r") as f:
        names = sorted((k for k in f["data"] if k.startswith("demo_")), key=lambda k: int(k.split("_")[1]))
        return [f[f"data/{k}/actions"][()] for k in names]


def gripper_width(gripper: np.ndarray) -> np.ndarray:
    return gripper[:, 0] - gripper[:, 1]


def phase_bounds(actions: np.ndarray, ee_pos: np.ndarray) -> dict[str, int]:
    """Start step of each phase of one demonstration, from its gripper command and end-effector height.

    approach: until the gripper is first commanded closed; grasp: until the end effector has risen LIFT_RISE_M
    above where it closed; lift: until it is within TOP_MARGIN_M of its highest point before the release; carry/
    place: until the gripper is commanded open again; release: the rest. A phase that never starts begins at N.
    """
    n = len(actions)
    closed = actions[:, 6] > 0
    close = int(np.argmax(closed)) if closed.any() else n
    reopen = n
    if close < n:
        opened = np.nonzero(~closed[close:])[0]
        reopen = close + int(opened[0]) if len(opened) else n
    z = ee_pos[:, 2]
    lift = n
    if close < n:
        risen = np.nonzero(z[close:reopen] > z[close] + LIFT_RISE_M)[0]
        lift = close + int(risen[0]) if len(risen) else reopen
    carry = reopen
    if lift < reopen:
        top = z[lift:reopen].max()
        near = np.nonzero(z[lift:reopen] >= top - TOP_MARGIN_M)[0]
        carry = lift + int(near[0])
    return dict(zip(PHASES, (0, close, lift, carry, reopen), strict=True))


def phase_of(step: int, bounds: dict[str, int]) -> str:
    name = PHASES[0]
    for phase in PHASES:
        if step >= bounds[phase]:
            name = phase
    return name


def fixtures_from_model_xml(env, xml: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The fixture poses a demonstration's saved scene XML holds (resets jitter fixtures outside the sim state)."""
    from lerobot_predvla.libero.env import fixture_poses

    wanted = fixture_poses(env)
    root = ElementTree.fromstring(xml)
    out = {}
    for body in root.iter("body"):
        name = body.get("name")
        if name in wanted and body.get("pos") is not None:
            pos = np.array([float(v) for v in body.get("pos").split()])
            quat = np.array([float(v) for v in body.get("quat").split()]) if body.get("quat") else wanted[name][1]
            out[name] = (pos, quat)
    return out


def target_object(env) -> str:
    """The object the instruction asks to move (LIBERO's first object of interest)."""
    return env.env.obj_of_interest[0]


def simulate(env, demo: Demo, actions: np.ndarray, cap: int, stop_at_success: bool) -> dict[str, np.ndarray | int]:
    """Start from the demonstration's first state and run `actions` (then idle steps up to `cap` when they are
    fewer). Records, before each action as the demonstrations do, the end-effector position, joint angles,
    finger positions and the target object's position; `success_step` is the first step after which the task's
    goal holds (-1: never)."""
    from lerobot_predvla.libero.env import set_fixture_poses
    from lerobot_predvla.libero.rollout import IDLE

    env.reset()
    set_fixture_poses(env, fixtures_from_model_xml(env, demo.model_xml))
    obs = env.regenerate_obs_from_state(demo.states[0])
    # OSC's nullspace term pulls the arm toward the joints it held at reset: the demonstrations were recorded with
    # the reset's own (noisy) start there, so the start's joints take its place.
    env.env.robots[0].controller.update_initial_joints(demo.joints[0])
    target = target_object(env)
    rec = {k: [] for k in ("ee_pos", "ee_quat", "joints", "gripper", "object_pos")}
    success = -1
    for t in range(cap):
        rec["ee_pos"].append(np.asarray(obs["robot0_eef_pos"]).copy())
        rec["ee_quat"].append(np.asarray(obs["robot0_eef_quat"]).copy())
        rec["joints"].append(np.asarray(obs["robot0_joint_pos"]).copy())
        rec["gripper"].append(np.asarray(obs["robot0_gripper_qpos"]).copy())
        rec["object_pos"].append(np.asarray(obs[f"{target}_pos"]).copy())
        obs, *_ = env.step(actions[t] if t < len(actions) else IDLE)
        if success < 0 and env.check_success():
            success = t + 1
            if stop_at_success:
                break
    out = {k: np.stack(v) for k, v in rec.items()}
    out["success_step"] = success
    out["target"] = target
    return out


def first_run(mask: np.ndarray, run: int = 1) -> int:
    """First index where `mask` holds for `run` consecutive steps (-1: never)."""
    count = 0
    for i, m in enumerate(mask):
        count = count + 1 if m else 0
        if count >= run:
            return i - run + 1
    return -1


def orientation_error(quat_xyzw: np.ndarray, axis_angle: np.ndarray) -> np.ndarray:
    """Angle (rad) between end-effector orientations given as robosuite quaternions (x, y, z, w) and as the
    demonstrations' axis-angle vectors."""
    angle = np.linalg.norm(axis_angle, axis=-1, keepdims=True)
    axis = axis_angle / np.maximum(angle, 1e-12)
    demo_quat = np.concatenate([axis * np.sin(angle / 2), np.cos(angle / 2)], axis=-1)
    q = quat_xyzw / np.linalg.norm(quat_xyzw, axis=-1, keepdims=True)
    return 2 * np.arccos(np.clip(np.abs((q * demo_quat).sum(-1)), 0.0, 1.0))


def compare(rollout: dict, demo: Demo, bounds: dict[str, int]) -> dict:
    """A rollout against the demonstration's own trajectory, over the steps both have."""
    n = min(len(rollout["ee_pos"]), len(demo.ee_pos))
    ee = np.linalg.norm(rollout["ee_pos"][:n] - demo.ee_pos[:n], axis=1)
    angle = orientation_error(rollout["ee_quat"][:n], demo.ee_ori[:n])
    joint = np.linalg.norm(rollout["joints"][:n] - demo.joints[:n], axis=1)
    grip = np.abs(gripper_width(rollout["gripper"][:n]) - gripper_width(demo.gripper[:n]))
    separation = {}
    for threshold in SEPARATION_THRESHOLDS_M:
        step = first_run(ee > threshold)
        separation[f"{threshold * 100:g}cm"] = {"step": step, "phase": phase_of(step, bounds) if step >= 0 else None}
    per_phase = {}
    ends = [bounds[p] for p in PHASES[1:]] + [len(demo.ee_pos)]
    for phase, end in zip(PHASES, ends, strict=True):
        lo, hi = bounds[phase], min(end, n)
        if hi > lo:
            per_phase[phase] = {"steps": [lo, hi], "ee_mean_m": float(ee[lo:hi].mean()),
                                "ee_max_m": float(ee[lo:hi].max()), "ee_at_end_m": float(ee[hi - 1]),
                                "orientation_mean_rad": float(angle[lo:hi].mean()),
                                "joint_mean_rad": float(joint[lo:hi].mean()),
                                "joint_max_rad": float(joint[lo:hi].max())}
    obj = rollout["object_pos"]
    close = min(bounds["grasp"], n - 1)  # where the demonstration closes its gripper
    return {
        "at_demo_close": {"step": close, "ee_distance_m": float(ee[close]), "ee_dxyz_m":
                          (rollout["ee_pos"][close] - demo.ee_pos[close]).tolist(),
                          "orientation_error_rad": float(angle[close]),
                          "joint_error_per_joint_rad": (rollout["joints"][close] - demo.joints[close]).tolist()},
        "steps_compared": n,
        "success_step": int(rollout["success_step"]),
        "separation": separation,
        "per_phase": per_phase,
        "ee_mean_m": float(ee.mean()), "ee_max_m": float(ee.max()),
        "joint_mean_rad": float(joint.mean()), "joint_max_rad": float(joint.max()),
        "orientation_mean_rad": float(angle.mean()), "orientation_max_rad": float(angle.max()),
        "gripper_width_mean_abs_m": float(grip.mean()),
        "object_rise_max_m": float(obj[:, 2].max() - obj[0, 2]),
        "object_moved_xy_max_m": float(np.linalg.norm(obj[:, :2] - obj[0, :2], axis=1).max()),
        "min_ee_height_m": float(rollout["ee_pos"][:, 2].min()),
        "curves": {"ee_distance_m": ee, "joint_error_rad": joint, "orientation_error_rad": angle},
    }


def offline_actions(open_loop: np.ndarray, demos: list[np.ndarray]) -> dict:
    """Open-loop actions (raw units) against every demonstration of the task, per step.

    `mse_vs_demos`: mean over the demonstrations still running at that step of the squared error (mean over the 7
    dimensions); `mse_vs_mean`: against the time-aligned mean demonstration; `demo_spread`: the demonstrations'
    own mean squared distance from that mean (what no observation-blind chain can get below); the envelope is the
    demonstrations' min and max per step and dimension, where at least ENVELOPE_MIN_DEMOS of them still run.
    """
    longest = max(len(a) for a in demos)
    horizon = min(longest, len(open_loop))
    stack = np.full((len(demos), longest, 7), np.nan)
    for i, a in enumerate(demos):
        stack[i, :len(a)] = a
    active = (~np.isnan(stack[..., 0])).sum(0)
    enough = active >= ENVELOPE_MIN_DEMOS * len(demos)
    horizon = min(horizon, int(np.nonzero(enough)[0].max()) + 1)
    stack = stack[:, :horizon]
    ol = open_loop[:horizon]
    mean = np.nanmean(stack, axis=0)
    sq = (stack - ol[None]) ** 2  # (demos, T, 7)
    mse_vs_demos = np.nanmean(sq.mean(-1), axis=0)
    mse_vs_mean = ((ol - mean) ** 2).mean(-1)
    spread = np.nanmean(((stack - mean[None]) ** 2).mean(-1), axis=0)
    low, high = np.nanmin(stack, axis=0), np.nanmax(stack, axis=0)
    std = np.nanstd(stack, axis=0)
    outside = (ol < low - ENVELOPE_MARGIN) | (ol > high + ENVELOPE_MARGIN)  # (T, 7)
    exits = {str(k): first_run(outside[:, k], EXIT_RUN) for k in range(7)}
    z = np.abs(ol - mean) / np.maximum(std, 1e-6)
    return {
        "horizon": horizon,
        "mse_vs_demos": mse_vs_demos, "mse_vs_mean": mse_vs_mean, "demo_spread": spread,
        "mean": mean, "low": low, "high": high, "std": std,
        "inside_fraction_per_dim": (~outside).mean(0).tolist(),
        "inside_fraction_all_dims": float((~outside).all(1).mean()),
        "first_exit_step_per_dim": exits,
        "first_exit_step_any_dim": first_run(outside.any(1), EXIT_RUN),
        "median_abs_z_per_dim": np.median(z, axis=0).tolist(),
    }


def median_bounds(all_bounds: list[dict[str, int]]) -> dict[str, int]:
    return {p: int(np.median([b[p] for b in all_bounds])) for p in PHASES}


def phase_means(curve: np.ndarray, bounds: dict[str, int]) -> dict[str, float]:
    ends = [bounds[p] for p in PHASES[1:]] + [len(curve)]
    return {p: float(np.mean(curve[bounds[p]:min(e, len(curve))])) for p, e in zip(PHASES, ends, strict=True)
            if min(e, len(curve)) > bounds[p]}


class OpenLoop:
    """A checkpoint's exact open-loop actions per instruction, raw units (through its postprocessor)."""

    def __init__(self, checkpoint: Path):
        import torch
        from lerobot.processor import PolicyProcessorPipeline
        from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action

        from lerobot_predvla.frontend.artefact import FrontendArtefact
        from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy

        self.checkpoint = Path(checkpoint)
        self.policy = PredVLAPolicy.from_pretrained(self.checkpoint).eval()
        self.policy.config.er_iterations = 0
        self.postprocessor = PolicyProcessorPipeline.from_pretrained(
            self.checkpoint, "policy_postprocessor.json", to_transition=policy_action_to_transition,
            to_output=transition_to_policy_action)
        self.artefact = FrontendArtefact.load(self.checkpoint / "predvla_frontend")
        self._torch = torch
        self._encoder = None

    def language(self, instruction: str):
        from lerobot_predvla.frontend.language import LanguageEncoder

        if self._encoder is None:
            self._encoder = LanguageEncoder("cpu", verbose=False)
        torch = self._torch
        with torch.no_grad():
            return self.artefact.language.transform(torch.from_numpy(self._encoder([instruction])))

    def normalised(self, instruction: str, steps: int):
        from lerobot_predvla.policies.predvla.diagnostics import open_loop

        return open_loop(self.policy, self.language(instruction), steps)[:, 0]  # (steps, 7)

    def actions(self, instruction: str, steps: int) -> np.ndarray:
        with self._torch.no_grad():
            raw = self.postprocessor(self.normalised(instruction, steps))
        return raw.detach().cpu().double().numpy()


EFFECT_WINDOWS = ((0, 5), (5, 10), (10, 20), (20, 50), (50, None))


def instruction_effect(own: np.ndarray, others: list[np.ndarray], horizon: int) -> np.ndarray:
    """Per step, the mean over `others` of the squared difference from `own` (mean over the 7 dimensions), NaN where
    an other sequence has ended: how much the instruction changes the actions at each step."""
    diffs = np.full((len(others), horizon), np.nan)
    for i, other in enumerate(others):
        k = min(horizon, len(other), len(own))
        diffs[i, :k] = ((own[:k] - other[:k]) ** 2).mean(-1)
    if not len(others):
        return np.full(horizon, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # steps where every other sequence has ended: NaN
        return np.nanmean(diffs, axis=0)


def window_means(curve: np.ndarray) -> dict[str, float]:
    out = {}
    for lo, hi in EFFECT_WINDOWS:
        part = curve[lo:hi]
        if len(part) and not np.isnan(part).all():
            out[f"{lo}-{hi if hi is not None else len(curve)}"] = float(np.nanmean(part))
    return out


def mean_demo(actions: list[np.ndarray]) -> np.ndarray:
    """Time-aligned mean of demonstrations, up to the step where fewer than ENVELOPE_MIN_DEMOS of them run."""
    longest = max(len(a) for a in actions)
    stack = np.full((len(actions), longest, 7), np.nan)
    for i, a in enumerate(actions):
        stack[i, :len(a)] = a
    enough = (~np.isnan(stack[..., 0])).sum(0) >= ENVELOPE_MIN_DEMOS * len(actions)
    return np.nanmean(stack[:, :int(np.nonzero(enough)[0].max()) + 1], axis=0)


def run_task(open_loop: OpenLoop, hdf5_root: Path, task_id: int, demos: int, cap: int, suite: str = "libero_object",
             log=print, other_open_loops: dict[int, np.ndarray] | None = None,
             other_mean_demos: dict[int, np.ndarray] | None = None) -> tuple[dict, dict]:
    """The simulator and offline comparisons of one task: (numbers for the JSON, arrays for the figure)."""
    from lerobot_predvla.libero.env import make_env, task_spec

    spec = task_spec(suite, task_id)
    path = demo_file(hdf5_root, suite, spec.name)
    all_actions = read_all_actions(path)
    n_file = len(all_actions)
    chosen = list(range(min(demos, n_file)))
    chosen_demos = read_demos(path, chosen)
    ol = open_loop.actions(spec.language, cap)
    env = make_env(spec)
    rows, curves = [], []
    for demo in chosen_demos:
        bounds = phase_bounds(demo.actions, demo.ee_pos)
        other = (demo.index + 1) % n_file
        rollouts = {
            "replay": simulate(env, demo, demo.actions, len(demo.actions), stop_at_success=False),
            "open_loop": simulate(env, demo, ol, cap, stop_at_success=True),
        }
        # The open loop with its rotation commands replaced by the demonstration's own (zero past its end): how much
        # of the failure the end effector's orientation carries.
        own_rotation = ol.copy()
        own_rotation[:, 3:6] = 0.0
        k = min(len(ol), len(demo.actions))
        own_rotation[:k, 3:6] = demo.actions[:k, 3:6]
        rollouts["open_loop_demo_rotation"] = simulate(env, demo, own_rotation, cap, stop_at_success=True)
        if other != demo.index:
            rollouts["blind_plan"] = simulate(env, demo, all_actions[other],
                                              min(cap, len(all_actions[other]) + BLIND_IDLE_STEPS),
                                              stop_at_success=True)
        cmp = {name: compare(r, demo, bounds) for name, r in rollouts.items()}
        steps = min(len(demo.actions), len(ol))
        action_err = ((ol[:steps] - demo.actions[:steps]) ** 2).mean(-1)
        row = {"demo": demo.index, "length": len(demo.actions), "phases": bounds,
               "blind_plan_demo": other if other != demo.index else None,
               "open_loop_action_mse_vs_this_demo": float(action_err.mean()),
               "open_loop_action_mse_vs_this_demo_per_phase": phase_means(action_err, bounds),
               "open_loop_first_close_step": int(np.argmax(ol[:, 6] > 0)) if (ol[:, 6] > 0).any() else -1,
               # Translation commands summed up to the demonstration's close step (action units; OSC_POSE moves the
               # target 5 cm per unit and step): how far each asks the hand to go before grasping.
               "commanded_xyz_sum_to_demo_close": {
                   "open_loop": ol[:bounds["grasp"], :3].sum(0).tolist(),
                   "demo": demo.actions[:bounds["grasp"], :3].sum(0).tolist()},
               **{name: {k: v for k, v in c.items() if k != "curves"} for name, c in cmp.items()}}
        rows.append(row)
        curves.append({"demo": demo, "bounds": bounds, "rollouts": rollouts, "cmp": cmp, "action_err": action_err})
        sep = cmp["open_loop"]["separation"]
        log(f"task {task_id} demo {demo.index}: open loop leaves the demo by 2 cm at step {sep['2cm']['step']} "
            f"({sep['2cm']['phase']}), 5 cm at {sep['5cm']['step']} ({sep['5cm']['phase']}); success step "
            f"{cmp['open_loop']['success_step']} (with the demo's rotation: "
            f"{cmp['open_loop_demo_rotation']['success_step']}"
            f"; another demo's plan: {cmp.get('blind_plan', {}).get('success_step')}); own replay max "
            f"{cmp['replay']['ee_max_m'] * 100:.2f} cm")
    env.close()
    all_bounds = []
    with __import__("h5py").File(path, "r") as f:
        for k in range(n_file):
            g = f[f"data/demo_{k}"]
            all_bounds.append(phase_bounds(g["actions"][()], g["obs/ee_pos"][()]))
    offline = offline_actions(ol, all_actions)
    med = median_bounds(all_bounds)
    h = offline["horizon"]
    others = {k: v for k, v in (other_open_loops or {}).items() if k != task_id}
    other_demos = {k: v for k, v in (other_mean_demos or {}).items() if k != task_id}
    offline["instruction_effect_open_loop"] = instruction_effect(ol, list(others.values()), h)
    offline["instruction_effect_demos"] = instruction_effect(mean_demo(all_actions), list(other_demos.values()), h)
    exits = offline["first_exit_step_per_dim"]
    numbers = {
        "task_id": task_id, "task": spec.name, "instruction": spec.language, "demo_file": str(path),
        "demos_in_file": n_file, "demos_simulated": chosen,
        "median_phase_starts_all_demos": med,
        "demos": rows,
        "offline": {
            "horizon": offline["horizon"],
            "open_loop_mse_vs_demos": float(np.mean(offline["mse_vs_demos"])),
            "open_loop_mse_vs_mean_demo": float(np.mean(offline["mse_vs_mean"])),
            "demo_spread_mse": float(np.mean(offline["demo_spread"])),
            "per_phase": {
                "open_loop_mse_vs_demos": phase_means(offline["mse_vs_demos"], med),
                "open_loop_mse_vs_mean_demo": phase_means(offline["mse_vs_mean"], med),
                "demo_spread_mse": phase_means(offline["demo_spread"], med),
            },
            "inside_envelope_fraction_per_dim": offline["inside_fraction_per_dim"],
            "inside_envelope_fraction_all_dims": offline["inside_fraction_all_dims"],
            "first_exit_step_per_dim": exits,
            "first_exit_phase_per_dim": {k: (phase_of(s, med) if s >= 0 else None) for k, s in exits.items()},
            "first_exit_step_any_dim": offline["first_exit_step_any_dim"],
            "median_abs_z_per_dim": offline["median_abs_z_per_dim"],
            # How much the instruction changes the actions, by step window: this task's open loop against the open
            # loop under each other instruction of the suite, and its mean demonstration against the other tasks'
            # mean demonstrations (those whose files exist).
            "instruction_effect": {
                "open_loop_vs_other_instructions": window_means(offline["instruction_effect_open_loop"]),
                "mean_demo_vs_other_tasks": window_means(offline["instruction_effect_demos"]),
                "other_instructions": sorted(others), "other_tasks_with_demos": sorted(other_demos)},
        },
    }
    return numbers, {"curves": curves, "offline": offline, "open_loop": ol, "median_bounds": med, "spec": spec}


PHASE_COLOURS = {"approach": "0.95", "grasp": "#fde0c5", "lift": "#d9f0d3", "carry/place": "#dbe9f6",
                 "release": "#eadcf2"}
ROT_LS = (0, (6, 2, 1, 2))
ACTION_NAMES = ("dx", "dy", "dz", "droll", "dpitch", "dyaw", "gripper")


def shade(ax, bounds: dict[str, int], end: int, labels: bool = False) -> None:
    ends = [bounds[p] for p in PHASES[1:]] + [end]
    for phase, e in zip(PHASES, ends, strict=True):
        if e > bounds[phase]:
            ax.axvspan(bounds[phase], e, color=PHASE_COLOURS[phase], lw=0, zorder=0,
                       label=phase if labels else None)


def plot_task(path: Path, arrays: dict, numbers: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lerobot_predvla.utils.io import atomic_save_figure

    curves, offline = arrays["curves"], arrays["offline"]
    first = curves[0]
    fig, axes = plt.subplots(4, 4, figsize=(19, 13))
    colours = [f"C{i}" for i in range(len(curves))]
    end = max(len(c["demo"].actions) for c in curves)
    xmax = max(end, *(len(c["rollouts"]["open_loop"]["ee_pos"]) for c in curves))
    for k, label in enumerate(("x", "y", "z")):
        ax = axes[0, k]
        shade(ax, first["bounds"], len(first["demo"].actions), labels=k == 0)
        for c, col in zip(curves, colours, strict=True):
            ax.plot(c["demo"].ee_pos[:, k], color=col, lw=1.5, label=f"demo {c['demo'].index}")
            ax.plot(c["rollouts"]["open_loop"]["ee_pos"][:, k], color=col, lw=1, ls="--",
                    label="open loop" if c is first else None)
            if "blind_plan" in c["rollouts"]:
                ax.plot(c["rollouts"]["blind_plan"]["ee_pos"][:, k], color=col, lw=0.8, ls=":",
                        label="another demo's plan, blind" if c is first else None)
            ax.plot(c["rollouts"]["open_loop_demo_rotation"]["ee_pos"][:, k], color=col, lw=0.7, ls=ROT_LS,
                    alpha=0.8, label="open loop, demo's rotation" if c is first else None)
        ax.set(title=f"end effector {label} (m); solid demo, dashed open loop", xlim=(0, xmax))
    axes[0, 0].legend(fontsize=7, loc="best")
    ax = axes[0, 3]
    shade(ax, first["bounds"], len(first["demo"].actions))
    for c, col in zip(curves, colours, strict=True):
        ax.plot(gripper_width(c["demo"].gripper), color=col, lw=1.5)
        ax.plot(gripper_width(c["rollouts"]["open_loop"]["gripper"]), color=col, lw=1, ls="--")
        ax.plot(c["rollouts"]["open_loop"]["object_pos"][:, 2] - c["rollouts"]["open_loop"]["object_pos"][0, 2],
                color=col, lw=0.8, ls="-.")
    ax.set(title="gripper width (m; solid demo, dashed open loop);\nopen loop's target object rise (m, dash-dot)",
           xlim=(0, xmax))
    panels = ((axes[1, 0], "ee_distance_m", "end-effector distance to the demo (m)"),
              (axes[1, 1], "joint_error_rad", "joint error to the demo (rad, L2 over 7 joints)"),
              (axes[1, 2], "orientation_error_rad", "end-effector orientation error to the demo (rad)"))
    for ax, key, title in panels:
        shade(ax, first["bounds"], len(first["demo"].actions))
        for c, col in zip(curves, colours, strict=True):
            ax.plot(c["cmp"]["open_loop"]["curves"][key], color=col, lw=1.2,
                    label="open loop" if c is first else None)
            if "blind_plan" in c["cmp"]:
                ax.plot(c["cmp"]["blind_plan"]["curves"][key], color=col, lw=0.8, ls=":",
                        label="another demo's plan, blind" if c is first else None)
            ax.plot(c["cmp"]["replay"]["curves"][key], color=col, lw=0.8, ls="-.",
                    label="own actions replayed" if c is first else None)
            ax.plot(c["cmp"]["open_loop_demo_rotation"]["curves"][key], color=col, lw=0.7, ls=ROT_LS, alpha=0.8,
                    label="open loop, demo's rotation" if c is first else None)
        if key == "ee_distance_m":
            for th in (0.02, 0.05):
                ax.axhline(th, color="0.5", lw=0.6, ls="--")
        ax.set(title=title + "\nphases of the first demo shaded", yscale="log", xlim=(0, end))
        ax.legend(fontsize=7)
    ax = axes[1, 3]
    med = arrays["median_bounds"]
    h = offline["horizon"]
    shade(ax, med, h)
    ax.plot(offline["mse_vs_demos"], "k", lw=1.2, label="open loop vs every demo (mean)")
    ax.plot(offline["mse_vs_mean"], "C3", lw=1, label="open loop vs mean demo")
    ax.plot(offline["demo_spread"], "0.5", lw=1, ls="--", label="demos vs mean demo (spread)")
    ax.plot(offline["instruction_effect_open_loop"], "C4", lw=1, ls=":",
            label="open loop vs other instructions' open loop")
    ax.plot(offline["instruction_effect_demos"], "C2", lw=1, ls=":", label="mean demo vs other tasks' mean demos")
    for c, col in zip(curves, colours, strict=True):
        ax.plot(c["action_err"], color=col, lw=0.6, alpha=0.7)
    ax.set(title=f"action MSE per step, raw units (all {numbers['demos_in_file']} demos; thin: vs each\n"
                 "simulated demo); phases from here on: median over the demos", yscale="log", xlim=(0, h))
    ax.legend(fontsize=7)
    ol = arrays["open_loop"]
    for ax, k in zip([*axes[2], *axes[3][:3]], range(7), strict=True):
        shade(ax, med, h)
        ax.fill_between(range(h), offline["low"][:, k], offline["high"][:, k], color="0.75", lw=0,
                        label="demos' min-max")
        ax.plot(offline["mean"][:, k], "k", lw=1, label="mean demo")
        ax.plot(ol[:h, k], "C3", lw=1.2, label="open loop")
        exit_step = numbers["offline"]["first_exit_step_per_dim"][str(k)]
        if exit_step >= 0:
            ax.axvline(exit_step, color="C3", lw=0.6, ls=":")
        ax.set(title=f"action {ACTION_NAMES[k]}: the demos' envelope (dotted: open loop leaves it)", xlim=(0, h))
        if k == 0:
            ax.legend(fontsize=7)
    axes[3, 3].axis("off")
    for ax in axes.flat:
        ax.set_xlabel("control step")
        ax.title.set_fontsize(8)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"task {numbers['task_id']}: {numbers['instruction']}: exact open loop from each demo's own start",
                 fontsize=11)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=80)
    plt.close(fig)


def run(checkpoint: Path, hdf5_root: Path, tasks: list[int], demos: int, cap: int, out: Path,
        suite: str = "libero_object", log=print, merge: bool = False) -> dict:
    """Writes OUT/task<k>.png, OUT/divergence.json and OUT/summary.md. With `merge`, the tasks of an existing
    OUT/divergence.json of the same checkpoint, demonstrations and cap are kept (their figures stay as they are)
    and the tasks run now are added or replaced."""
    from lerobot_predvla.utils.io import atomic_write_json

    out.mkdir(parents=True, exist_ok=True)
    from lerobot_predvla.libero.env import num_tasks, task_spec

    open_loop = OpenLoop(checkpoint)
    other_open_loops, other_mean_demos = {}, {}
    for k in range(num_tasks(suite)):
        spec = task_spec(suite, k)
        other_open_loops[k] = open_loop.actions(spec.language, cap)
        path = demo_file(hdf5_root, suite, spec.name)
        if path.is_file():
            other_mean_demos[k] = mean_demo(read_all_actions(path))
    # How much the instruction changes the actions at each step, for every task of the suite (offline): the open
    # loop against the open loop under each other instruction, the mean demonstration against the other tasks'.
    effect = {}
    for k, ol_k in other_open_loops.items():
        if k not in other_mean_demos:
            continue
        h = min(len(other_mean_demos[k]), cap)
        effect[str(k)] = {
            "open_loop_vs_other_instructions": window_means(instruction_effect(
                ol_k, [v for j, v in other_open_loops.items() if j != k], h)),
            "mean_demo_vs_other_tasks": window_means(instruction_effect(
                other_mean_demos[k], [v for j, v in other_mean_demos.items() if j != k], h)),
            "other_tasks_with_demos": sorted(j for j in other_mean_demos if j != k)}
    report = {"checkpoint": str(checkpoint), "hdf5_root": str(hdf5_root), "suite": suite, "cap": cap,
              "demos_per_task": demos, "separation_thresholds_m": list(SEPARATION_THRESHOLDS_M),
              "phase_rule": {"lift_rise_m": LIFT_RISE_M, "top_margin_m": TOP_MARGIN_M},
              "envelope": {"min_demo_fraction": ENVELOPE_MIN_DEMOS, "exit_run_steps": EXIT_RUN,
                           "margin": ENVELOPE_MARGIN},
              "blind_idle_steps": BLIND_IDLE_STEPS, "instruction_effect_windows": [list(w) for w in EFFECT_WINDOWS],
              "instruction_effect_by_task": effect, "tasks": {}}
    previous = out / "divergence.json"
    if merge and previous.is_file():
        old = load_report(previous)
        same = ("checkpoint", "hdf5_root", "suite", "cap")
        if any(old.get(k) != report[k] for k in same):
            raise ValueError(f"{previous}: another run ({', '.join(f'{k}={old.get(k)}' for k in same)}); cannot merge")
        report["tasks"] = {k: v for k, v in old["tasks"].items() if int(k) not in tasks}
        report["merged_from_earlier_runs"] = sorted(report["tasks"], key=int)
    for task_id in tasks:
        numbers, arrays = run_task(open_loop, hdf5_root, task_id, demos, cap, suite, log, other_open_loops,
                                   other_mean_demos)
        report["tasks"][str(task_id)] = numbers
        atomic_write_json(out / "divergence.json", report)  # before the figure: the numbers are the costly part
        plot_task(out / f"task{task_id}.png", arrays, numbers)
    report["tasks"] = dict(sorted(report["tasks"].items(), key=lambda kv: int(kv[0])))
    atomic_write_json(out / "divergence.json", report)
    (out / "summary.md").write_text(markdown_summary(report))
    return report


def load_report(path: Path) -> dict:
    return json.loads(Path(path).read_text())


def _cm(value: float) -> str:
    return f"{value * 100:.1f}"


def _sep(row: dict, name: str, key: str) -> str:
    sep = row[name]["separation"][key]
    return "never" if sep["step"] < 0 else f"{sep['step']} ({sep['phase']})"


def markdown_summary(report: dict) -> str:
    """The report's main numbers as markdown tables (what the write-up quotes)."""
    lines = ["| task | demo | length | phases (grasp, lift, carry, release) | open loop leaves by 2 cm | by 5 cm | "
             "at the demo's close: distance (cm), height above (cm), yaw error (rad) | open loop success | "
             "with the demo's rotation | another demo's plan, blind | own replay max (cm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        for row in task["demos"]:
            ph = row["phases"]
            close = row["open_loop"]["at_demo_close"]
            blind = row.get("blind_plan")

            def success(r):
                return "no" if r["success_step"] < 0 else f"step {r['success_step']}"

            lines.append(
                f"| {task_id} | {row['demo']} | {row['length']} | {ph['grasp']}, {ph['lift']}, {ph['carry/place']}, "
                f"{ph['release']} | {_sep(row, 'open_loop', '2cm')} | {_sep(row, 'open_loop', '5cm')} | "
                f"{_cm(close['ee_distance_m'])}, {_cm(close['ee_dxyz_m'][2])}, {close['orientation_error_rad']:.2f} | "
                f"{success(row['open_loop'])} | {success(row['open_loop_demo_rotation'])} | "
                f"{success(blind) if blind else '-'} | {_cm(row['replay']['ee_max_m'])} |")
    lines += ["", "| task | rollout | end-effector distance per phase, mean (cm): approach / grasp / lift / carry / "
              "release | joint error mean (rad) | lowest hand height (cm) | object lifted (cm) |",
              "|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        for name in ("open_loop", "open_loop_demo_rotation", "blind_plan"):
            rows = [r[name] for r in task["demos"] if name in r]
            if not rows:
                continue
            per_phase = " / ".join(
                _cm(np.mean([r["per_phase"][p]["ee_mean_m"] for r in rows if p in r["per_phase"]]))
                if any(p in r["per_phase"] for r in rows) else "-" for p in PHASES)
            lines.append(f"| {task_id} | {name} | {per_phase} | {np.mean([r['joint_mean_rad'] for r in rows]):.2f} | "
                         f"{', '.join(_cm(r['min_ee_height_m']) for r in rows)} | "
                         f"{', '.join(_cm(r['object_rise_max_m']) for r in rows)} |")
    lines += ["", "| task | action MSE: open loop vs demos / vs mean demo / demos' spread | per phase, open loop vs "
              "demos (approach, grasp, lift, carry, release) | inside the envelope (all 7 dims) | first exit step per "
              "dim (dx dy dz droll dpitch dyaw grip) | instruction effect steps 0-5 / 5-10 / 10-20: open loop, demos |",
              "|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        o = task["offline"]
        pp = o["per_phase"]["open_loop_mse_vs_demos"]
        eff = report.get("instruction_effect_by_task", {}).get(task_id) or o.get("instruction_effect", {})

        def windows(d):
            return " / ".join(f"{d[w]:.3f}" if w in d else "-" for w in ("0-5", "5-10", "10-20"))

        lines.append(
            f"| {task_id} | {o['open_loop_mse_vs_demos']:.3f} / {o['open_loop_mse_vs_mean_demo']:.3f} / "
            f"{o['demo_spread_mse']:.3f} | {', '.join(f'{pp[p]:.3f}' if p in pp else '-' for p in PHASES)} | "
            f"{o['inside_envelope_fraction_all_dims']:.0%} | "
            f"{' '.join(str(o['first_exit_step_per_dim'][str(k)]) for k in range(7))} | "
            f"{windows(eff.get('open_loop_vs_other_instructions', {}))}; "
            f"{windows(eff.get('mean_demo_vs_other_tasks', {}))} |")
    return "\n".join(lines) + "\n"
