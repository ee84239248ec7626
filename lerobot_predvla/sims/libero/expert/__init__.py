"""A scripted LIBERO expert on privileged simulator state, driving the default OSC_POSE controller.

The plan comes from the task's BDDL goal predicates (`In`/`On` become pick-and-place). One module per skill:
`motion` (control primitives), `grasp`, `place`, `push` and `articulate`.
"""

import numpy as np

from lerobot_predvla.sims.libero.expert.articulate import Articulating
from lerobot_predvla.sims.libero.expert.motion import (
    DEFAULT_HALF_TURN,
    HALF_TURN_RULES,
    MAX_FINGER_SPAN,
    MIN_GRASP_HEIGHT,
    OPEN,
    SKILL_ORDER,
    ExpertFailure,
    Skill,
)
from lerobot_predvla.sims.libero.expert.place import Placing
from lerobot_predvla.sims.libero.expert.push import Pushing
from lerobot_predvla.sims.libero.geometry import SceneView

__all__ = ["ExpertFailure", "ScriptedExpert"]


class ScriptedExpert(Placing, Pushing, Articulating):
    """Solves LIBERO goals (`In`, `On`, `Open`, `Close`, `Turnon`); call `act()` once per control step."""

    def __init__(self, env, speed: float = 1.0, rng: np.random.Generator | None = None,
                 half_turn: str = DEFAULT_HALF_TURN) -> None:
        if half_turn not in HALF_TURN_RULES:
            raise ValueError(f"half_turn must be one of {HALF_TURN_RULES}, got {half_turn!r}")
        self.half_turn = half_turn
        self.view = SceneView(env)
        self.goal = [tuple(p) for p in env.env.parsed_problem["goal_state"]]
        unsupported = [p for p in self.goal if p[0] not in SKILL_ORDER]
        if unsupported:
            raise ExpertFailure(f"no scripted plan for goal predicates {unsupported}")
        self.speed = speed
        self.rng = rng or np.random.default_rng()
        self._plan = self._run()
        self.done = False

    def _run(self) -> Skill:
        for predicate, *args in sorted(self.goal, key=lambda p: SKILL_ORDER[p[0]]):
            if predicate in ("in", "on"):
                obj, place = args
                box = self.view.box(obj)
                table_region = place in self.view.inner.object_sites_dict and self.view.site_parent(place) is None
                if predicate == "on" and table_region and box.short > MAX_FINGER_SPAN and box.height < MIN_GRASP_HEIGHT:
                    yield from self._push(obj, place)
                    continue
                out = self._opening(place) if predicate == "in" and place in self.view.inner.object_sites_dict else None
                if out is not None:
                    yield from self._slide_in(obj, place, out)
                    continue
                if predicate == "in" and self.view.joints(place):
                    if not self.view.holds("open", place):
                        yield from self._articulate(place, "open")
                    if self._drawer_spot(obj, place)[1] < 0.005:  # too tight to lower it in
                        yield from self._push_drawer_to_stop(place)
                target = self._target(predicate, place, obj)
                lift_z = target.clear_z + self.view.box(obj).height + 0.08
                yield from self._pick(obj, lift_z)
                yield from self._place(obj, predicate, place)
            elif not self.view.holds(predicate, args[0]):
                yield from self._articulate(args[0], predicate)

    def act(self) -> np.ndarray:
        """Next action; after the plan ends, holds still with the gripper open (`done` becomes True)."""
        try:
            return next(self._plan)
        except StopIteration:
            self.done = True
            return np.array([0, 0, 0, 0, 0, 0, OPEN], dtype=float)
