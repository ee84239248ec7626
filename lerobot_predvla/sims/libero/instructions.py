"""Evaluating a task with another task's instruction: is the language input used?

`--env.instruction_from_task=j` runs every selected task k of the suite with task j's instruction, and
`--env.instruction_shift=s` runs task k with task (k + s) mod n's (n the suite's tasks; s = 1 pairs every task with
the next one's instruction, a paired evaluation of all tasks). The scene, the official init states, the goal and the
success check stay task k's; only the text the policy reads changes: `lerobot-eval` puts each sub-environment's
`task_description` into the observation's `task` (`lerobot.scripts.lerobot_eval.rollout`), which PredVLA's language
encoder reads, so the env sets it to the other task's instruction. Every task's own and used instruction is
recorded in eval_info.json (`predvla_instructions`).
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class InstructionSource:
    """Which task of the same suite gives each evaluated task its instruction.

    Args:
        from_task: Every task gets this task's instruction (None: not used).
        shift: Task k gets task (k + shift) mod n's instruction (0: its own).
    """

    from_task: int | None = None
    shift: int = 0

    def __post_init__(self) -> None:
        if self.from_task is not None and self.shift != 0:
            raise ValueError("--env.instruction_from_task and --env.instruction_shift are alternatives; give one.")
        if self.from_task is not None and self.from_task < 0:
            raise ValueError(f"--env.instruction_from_task must be a task id >= 0, got {self.from_task}.")
        if self.shift < 0:
            raise ValueError(f"--env.instruction_shift must be >= 0, got {self.shift}.")

    @property
    def active(self) -> bool:
        return self.from_task is not None or self.shift != 0

    def task_for(self, task_id: int, num_tasks: int, suite: str) -> int:
        """The task whose instruction task `task_id` of `suite` (of `num_tasks` tasks) is run with."""
        if self.from_task is not None:
            if self.from_task >= num_tasks:
                raise ValueError(
                    f"--env.instruction_from_task={self.from_task}: {suite} has {num_tasks} tasks "
                    f"(ids 0-{num_tasks - 1})."
                )
            return self.from_task
        if self.shift != 0 and self.shift % num_tasks == 0:
            raise ValueError(
                f"--env.instruction_shift={self.shift} gives every task of {suite} ({num_tasks} tasks) its own "
                f"instruction; use 1-{num_tasks - 1}."
            )
        return (task_id + self.shift) % num_tasks


def instruction_summary(envs: dict) -> dict:
    """The `predvla_instructions` section of eval_info.json: per suite, each evaluated task's own instruction, the
    instruction it was run with and the task that instruction is from."""
    summary: dict[str, list[dict]] = {}
    for suite, tasks in envs.items():
        for vec_env in tasks.values():
            try:
                record = vec_env.get_attr("instruction_record")[0]
            except AttributeError:  # not a predvla_libero env
                continue
            summary.setdefault(suite, []).append(record)
    return {suite: sorted(records, key=lambda r: r["task_id"]) for suite, records in summary.items()}
