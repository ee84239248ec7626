"""The teleoperator model (sims/libero/expert/teleop.py) on a point-mass hand, without the simulator: a pick-and-place
script through the scripted expert's motion primitives, executed by the script and by the teleoperator."""

import numpy as np
import pytest

from lerobot_predvla.sims.libero.expert.motion import CLOSE, DOWN, OPEN, POS_SCALE, Motion
from lerobot_predvla.sims.libero.expert.teleop import TELEOP, TeleopMotion, TeleopParams, bezier, minimum_jerk
from research.demo_styles import noop_mask

OBJECT, TARGET = np.array([0.3, 0.1, 0.0]), np.array([-0.1, 0.35, 0.0])
RESPONSE = 0.4  # fraction of the commanded displacement the point-mass hand makes per step


class FakeView:
    """A hand that only translates, pointing down with its fingers along x."""

    def __init__(self) -> None:
        self.pos = np.array([0.0, -0.1, 0.2])

    def eef_pos(self) -> np.ndarray:
        return self.pos.copy()

    def eef_axis_z(self) -> np.ndarray:
        return DOWN.copy()

    def finger_axis(self) -> np.ndarray:
        return np.array([1.0, 0.0, 0.0])


class ScriptedHand(Motion):
    half_turn = "nearest"

    def __init__(self) -> None:
        self.view, self.speed = FakeView(), 1.0

    def plan(self):
        """The phases of `_pick` and `_place`, with their tolerances and caps."""
        above, lifted, over = OBJECT + [0, 0, 0.1], OBJECT + [0, 0, 0.15], TARGET + [0, 0, 0.15]
        yield from self._move(lambda: (above, None), OPEN, tol=0.01, max_steps=80, phase="approach")
        yield from self._move(lambda: (OBJECT, None), OPEN, tol=0.006, max_steps=50, max_speed=0.6, phase="descend")
        yield from self._hold(CLOSE, 12, phase="close")
        yield from self._move(lambda: (lifted, None), CLOSE, tol=0.02, max_steps=40, phase="lift")
        yield from self._move(lambda: (over, None), CLOSE, tol=0.02, max_steps=30, phase="carry")
        yield from self._move(lambda: (over, None), CLOSE, tol=0.01, max_steps=100)
        yield from self._move(lambda: (TARGET + [0, 0, 0.05], None), CLOSE, tol=0.01, max_steps=40, max_speed=0.5,
                              phase="lower")
        yield from self._hold(OPEN, 10, phase="release")


class TeleopHand(TeleopMotion, ScriptedHand):
    def __init__(self, params: TeleopParams, seed: int) -> None:
        super().__init__()
        self.start_operator(params, seed)

    def plan(self):
        yield from self._idle(self.start_idle)
        yield from super().plan()


def rollout(hand: ScriptedHand) -> tuple[np.ndarray, np.ndarray]:
    """(actions, hand positions before each action) of the whole plan."""
    actions, path = [], []
    for action in hand.plan():
        path.append(hand.view.pos.copy())
        actions.append(action)
        hand.view.pos = hand.view.pos + RESPONSE * POS_SCALE * np.asarray(action[:3])
    return np.array(actions), np.array(path)


def test_diversity_zero_is_the_script_bit_for_bit():
    scripted, _ = rollout(ScriptedHand())
    for seed in range(5):
        teleop, _ = rollout(TeleopHand(TELEOP.at(0.0), seed))
        assert teleop.shape == scripted.shape and np.array_equal(teleop, scripted)


def test_teleop_is_deterministic_per_seed_and_differs_between_seeds():
    a, _ = rollout(TeleopHand(TELEOP, 3))
    b, _ = rollout(TeleopHand(TELEOP, 3))
    c, _ = rollout(TeleopHand(TELEOP, 4))
    assert np.array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)
    assert np.abs(a).max() <= 1.0


def test_noop_fraction_grows_with_diversity():
    def fraction(diversity: float) -> float:
        runs = [rollout(TeleopHand(TELEOP.at(diversity), seed))[0] for seed in range(20)]
        return float(np.mean(np.concatenate([noop_mask(a) for a in runs])))

    f0, f_half, f1 = fraction(0.0), fraction(0.5), fraction(1.0)  # the point mass holds still exactly: f0 > 0
    assert f0 < f_half < f1 < f0 + 0.3


def test_the_approach_is_curved_and_starts_gently():
    """At diversity 1 the via-points spread the hand's path to above the object sideways across demonstrations
    (the script takes one path), and the hand's first step accelerates gradually instead of jumping to full speed."""
    _, scripted = rollout(ScriptedHand())
    middles, first_steps = [], []
    for seed in range(10):
        hand = TeleopHand(TELEOP, seed)
        _, path = rollout(hand)
        moving = path[hand.start_idle:]
        to_go = np.linalg.norm(moving - (OBJECT + [0, 0, 0.1]), axis=1)
        middles.append(moving[int(np.argmax(to_go < 0.5 * to_go[0]))])  # half way there
        first_steps.append(np.linalg.norm(moving[1] - moving[0]))
    assert np.sqrt(np.var(middles, axis=0).sum()) > 0.01
    assert max(first_steps) < 0.5 * np.linalg.norm(scripted[1] - scripted[0])


def test_minimum_jerk_bezier_is_smooth():
    t = np.linspace(0, 1, 201)
    s = np.array([minimum_jerk(x) for x in t])
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) >= 0)
    p0, p1, p2 = np.zeros(3), np.array([0.1, 0.1, 0.05]), np.array([0.2, 0.0, 0.0])
    path = np.array([bezier(p0, p1, p2, x) for x in s])
    velocity = np.diff(path, axis=0)
    assert np.linalg.norm(velocity[0]) < 1e-5 and np.linalg.norm(velocity[-1]) < 1e-5  # at rest at both ends
    jerk = np.diff(path, 3, axis=0)
    assert np.linalg.norm(jerk, axis=1).max() < 1e-5  # no kink: third differences stay small at this resolution


def test_params_scale_with_diversity():
    assert TELEOP.at(1.0) == TELEOP
    zero = TELEOP.at(0.0)
    assert zero.via_offset == zero.start_idle == zero.phase_idle_prob == zero.regrasp_prob == 0.0
    assert TELEOP.at(10.0).regrasp_prob == 1.0
    with pytest.raises(ValueError, match="diversity"):
        TELEOP.at(-0.5)


@pytest.mark.parametrize("argv, message", [
    (["--diversity", "0.5"], "--diversity 0.5 needs --style teleop"),
    (["--style", "teleop", "--diversity", "-1"], "--diversity must be >= 0"),
    (["--placement-spread-cm", "-3"], "--placement-spread-cm must be >= 0"),
])
def test_demos_refuses_bad_style_flags(argv, message):
    from lerobot_predvla.cli.main import main

    with pytest.raises(SystemExit, match=message):
        main(["demos", "--no-render", *argv])
