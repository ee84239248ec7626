"""The LIBERO evaluation protocol: suites, per-suite step caps and the paper's rollout counts (one definition)."""

SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
SHORT_SUITES = ("libero_spatial", "libero_goal", "libero_object")  # the paper's column order (Table 3)
SUITE_LABELS = {"libero_spatial": "spatial", "libero_goal": "goal", "libero_object": "object", "libero_10": "long"}

# Control-step cap per rollout when `--env.episode_length` is not given: LeRobot 0.6.1's
# `lerobot.envs.libero.TASK_SUITE_MAX_STEPS`, which `lerobot-eval` applies (each is above the suite's longest
# training demonstration: 193, 254, 270 and 505 steps). The 220 for libero_spatial seen elsewhere comes from
# OpenVLA's LIBERO evaluation script; LIBERO itself caps every suite at 600 (its `eval.max_steps`), which is
# the paper's protocol below. tests/test_libero_eval.py checks these against LeRobot's table.
STEP_CAPS = {"libero_spatial": 280, "libero_object": 280, "libero_goal": 300, "libero_10": 520}

PAPER_EPISODES_PER_TASK = 50  # Section 4: rollouts per task, from the official initial states
PAPER_EPISODE_LENGTH = 600  # Section 4.4: control-step cap per rollout
EVAL_ENV_TYPE = "predvla_libero"  # `--env.type` of LeRobot's LIBERO env with PredVLA's observations (envs/)
