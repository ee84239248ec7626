"""Varied placements at evaluation (`--env.placement_spread_cm=S`): the starts `predvla demos --placement-spread-cm S`
trains on, for `lerobot-eval`.

With `--env.init_states=false` every episode of `predvla_libero` starts from a randomised reset (LIBERO's placement
regions, drawn from numpy's generator seeded with the reset's seed). Right after that reset, before LeRobot's settle
steps (the no-op steps of `LiberoEnv.reset`), every movable object of the task is shifted by
`placement.episode_shift(env, seed, S / 100)`: the function `predvla demos` calls after its own randomised reset, with
the generator seeded by (reset seed, `placement.PLACEMENT_STREAM`). A demonstration whose episode seed equals an
evaluation episode's reset seed therefore starts from the same shifted placement: robosuite draws the arm's start
noise from the same generator whatever its magnitude, so the demonstrations' 0.02 rad against the evaluation's none
changes the arm, not the objects.

Reset seeds: `lerobot-eval --seed=s` gives episode i of every task the reset seed s + i (its `eval_policy` resets batch
b of `--eval.batch_size` n with seeds s + b * n ... s + b * n + n - 1, sub-environment j taking s + b * n + j, and
starts again from s for each task); each episode's record names its seed. Gymnasium's automatic resets of a
sub-environment that ended before the others of its batch carry no seed and start episodes lerobot-eval discards: they
are not shifted.

After the settle steps each episode is checked as `predvla demos` checks its own (`placement.settled`: every object
within 1 cm in x, y of where it was put). Unsettled episodes still run and count; every episode's offsets, placements
and verdict are listed in eval_info.json's `predvla_shifts` section (with `unsettled_episodes`), as the object shift's.
"""

import numpy as np

from lerobot_predvla.sims.libero.placement import episode_shift, movable_objects, object_positions, settled

CM = 0.01
FLAG = "--env.placement_spread_cm"


def check_placement(spread_cm: float, init_states: bool, object_shift: bool) -> None:
    """ValueError naming the flags when `spread_cm` is negative, asked for from the official init states, or combined
    with the object shift (`object_shift`: `--env.object_shift_cm` or `--env.target_shift_cm` is set)."""
    if not spread_cm >= 0:
        raise ValueError(f"{FLAG} must be >= 0 (cm, std per axis), got {spread_cm}.")
    if spread_cm == 0:
        return
    if object_shift:
        raise ValueError(f"{FLAG} cannot be combined with --env.object_shift_cm / --env.target_shift_cm: the one "
                         "shifts every object after a randomised reset, the others the object to pick (or its target) "
                         "from an official init state.")
    if init_states:
        raise ValueError(f"{FLAG} shifts the objects after LIBERO's randomised resets: it needs "
                         "--env.init_states=false.")


class PlacedResets:
    """The placement shift of one sub-environment: `place` right after each counted reset, `settle` after its settle
    steps."""

    def __init__(self, spread_cm: float) -> None:
        self.spread_cm = spread_cm
        self.seed: int | None = None  # reset seed of the episode being reset; None: place nothing
        self._pending: dict | None = None

    def place(self, env) -> None:
        """Shift every movable object of LIBERO ControlEnv `env`, just reset with `self.seed` (`episode_shift`)."""
        if self.seed is None:
            self._pending = None
            return
        try:
            offsets, note = episode_shift(env, self.seed, self.spread_cm * CM), ""
        except RuntimeError as err:  # no draw left every object free: the episode runs from the unshifted reset
            offsets, note = {}, str(err)
        names = movable_objects(env)
        self._pending = {"seed": self.seed, "names": names, "offsets": offsets, "placed": object_positions(env, names),
                         "note": note}

    def settle(self, env) -> dict:
        """This episode's record, after the reset's settle steps: seed, per object its offset (m), where it was put
        (x, y, m) and how far it moved while settling (x, y, cm), and whether every object settled."""
        pending, now = self._pending, object_positions(env, self._pending["names"])
        moved = np.linalg.norm(now[:, :2] - pending["placed"][:, :2], axis=1) / CM
        record = {"seed": pending["seed"], "spec": {"placement_spread_cm": self.spread_cm},
                  "offsets_m": {name: np.round(offset, 6).tolist() for name, offset in pending["offsets"].items()},
                  "placed_xy_m": {name: np.round(xyz[:2], 6).tolist()
                                  for name, xyz in zip(pending["names"], pending["placed"], strict=True)},
                  "settle_xy_cm": {name: round(float(m), 3) for name, m in zip(pending["names"], moved, strict=True)},
                  "settled": not pending["note"] and settled(pending["placed"], now)}
        return {**record, **({"note": pending["note"]} if pending["note"] else {})}
