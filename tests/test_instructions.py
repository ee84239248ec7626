"""Evaluating a task with another task's instruction (`--env.instruction_from_task`, `--env.instruction_shift`).

The unit tests cover which instruction each task gets and the flags' checks; the simulator tests run LeRobot's own
rollout, whose observation `task` the policy reads, on libero_goal (one scene, ten goals): the policy sees the other
task's instruction while success is still the evaluated task's, and `lerobot-eval` records the instructions.
"""

from types import SimpleNamespace

import pytest
import torch
from eval_factory import open_loop_eval
from torch import nn

from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv
from lerobot_predvla.sims.libero.instructions import InstructionSource, instruction_summary

TURN_ON_THE_STOVE, BOWL_ON_PLATE = 7, 8  # libero_goal's tasks 7 and 8


def test_each_task_gets_the_instruction_of_the_task_the_flags_name():
    assert [InstructionSource(shift=1).task_for(k, 10, "libero_goal") for k in range(10)] == [*range(1, 10), 0]
    assert [InstructionSource(shift=3).task_for(k, 10, "libero_goal") for k in (0, 8)] == [3, 1]
    assert {InstructionSource(from_task=4).task_for(k, 10, "libero_goal") for k in range(10)} == {4}
    assert InstructionSource().task_for(6, 10, "libero_goal") == 6 and not InstructionSource().active


@pytest.mark.parametrize(("source", "message"), [
    (dict(from_task=2, shift=1), "are alternatives; give one"),
    (dict(from_task=-1), "instruction_from_task must be a task id >= 0"),
    (dict(shift=-1), "instruction_shift must be >= 0"),
])
def test_bad_instruction_flags_are_named(source, message):
    with pytest.raises(ValueError, match=message):
        InstructionSource(**source)
    with pytest.raises(ValueError, match=message):  # at once, before any environment is built
        PredVLALiberoEnv(task="libero_goal", **{f"instruction_{key}": value for key, value in source.items()})


def test_out_of_range_instruction_flags_name_the_suite():
    with pytest.raises(ValueError, match=r"instruction_from_task=10: libero_goal has 10 tasks \(ids 0-9\)"):
        InstructionSource(from_task=10).task_for(0, 10, "libero_goal")
    with pytest.raises(ValueError, match=r"instruction_shift=20 gives every task of libero_goal .* use 1-9"):
        InstructionSource(shift=20).task_for(0, 10, "libero_goal")


def test_the_summary_lists_every_task_of_every_suite():
    def vec_env(task_id: int, used: int):
        record = {"task_id": task_id, "instruction_from_task": used}
        return SimpleNamespace(get_attr=lambda name: [record] if name == "instruction_record" else None)

    envs = {"libero_goal": {3: vec_env(3, 4), 1: vec_env(1, 2)}, "other": {0: SimpleNamespace(get_attr=_missing)}}
    assert instruction_summary(envs) == {"libero_goal": [{"task_id": 1, "instruction_from_task": 2},
                                                         {"task_id": 3, "instruction_from_task": 4}]}


def _missing(name):
    raise AttributeError(name)


# ----- in the simulator --------------------------------------------------------------------------------------------
class StoveTurner(nn.Module):
    """A policy that records the instruction it is given and, at its first step, turns the stove on (sets the knob of
    libero_goal's flat stove inside its turned-on range), then stays still."""

    def __init__(self, venv):
        super().__init__()
        self.venv, self.instructions = venv, []

    def reset(self) -> None:
        pass

    def select_action(self, observation: dict) -> torch.Tensor:
        if not self.instructions:
            env = self.venv.envs[0].unwrapped._env.env
            for joint in env.get_object("flat_stove_1").joints:
                env.sim.data.qpos[env.sim.model.get_joint_qpos_addr(joint)] = 1.0  # turned on from 0.5 rad
            env.sim.forward()
        self.instructions.append(list(observation["task"]))
        return torch.tensor([[0.0, 0, 0, 0, 0, 0, -1]])


def _rollout(task_id: int, **instruction_flags) -> tuple[list[list[str]], bool, dict]:
    """LeRobot's rollout of `task_id` for at most 2 steps: the instructions the policy read, whether the episode
    succeeded, and the env's instruction record."""
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
    from lerobot.scripts.lerobot_eval import rollout

    cfg = PredVLALiberoEnv(task="libero_goal", task_ids=[task_id], episode_length=2, render_interval=1000,
                           **instruction_flags)
    venv = cfg.create_envs(1)["libero_goal"][task_id]
    try:
        policy = StoveTurner(venv)
        env_pre, env_post = cfg.get_env_processors()
        actions = PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                          to_output=transition_to_policy_action)
        result = rollout(venv, policy, env_pre, env_post, PolicyProcessorPipeline(steps=[]), actions, seeds=[0])
        (summary,) = instruction_summary({"libero_goal": {task_id: venv}})["libero_goal"]
        return policy.instructions, bool(result["success"].any()), summary
    finally:
        venv.close()


@pytest.mark.simulator
def test_the_policy_reads_the_other_tasks_instruction_and_success_stays_the_tasks_own():
    # Task 7 (turn on the stove) with task 8's instruction: the policy reads "put the bowl on the plate", and turning
    # the stove on still succeeds (task 7's goal).
    seen, success, record = _rollout(TURN_ON_THE_STOVE, instruction_shift=1)
    assert seen == [["put the bowl on the plate"]] and success
    assert record == {"task_id": 7, "task": "turn_on_the_stove", "own_instruction": "turn on the stove",
                      "instruction": "put the bowl on the plate", "instruction_from_task": 8}
    # Task 8 (bowl on the plate) told to turn on the stove: the stove is on, but task 8's goal is not reached.
    seen, success, record = _rollout(BOWL_ON_PLATE, instruction_from_task=TURN_ON_THE_STOVE)
    assert seen == [["turn on the stove"]] * 2 and not success
    assert (record["own_instruction"], record["instruction_from_task"]) == ("put the bowl on the plate", 7)


@pytest.mark.simulator
def test_lerobot_eval_records_the_instruction_of_each_task(tmp_path):
    """The committed checkpoint in exact open loop, one 3-step episode per task, tasks 1 and 2 each with task 3's
    instruction."""
    info = open_loop_eval(tmp_path / "eval", "[1,2]", "--env.instruction_from_task=3")
    records = info["predvla_instructions"]["libero_object"]
    assert [(r["task_id"], r["instruction_from_task"]) for r in records] == [(1, 3), (2, 3)]
    assert {r["instruction"] for r in records} == {"pick up the bbq sauce and place it in the basket"}
    assert records[0]["own_instruction"] != records[0]["instruction"]
