"""A teleoperator model of the scripted expert (`predvla demos --style teleop`): the same plan and the same closed
loop on privileged state, with the operator's intent perturbed the way human teleoperation differs from a script.

What is public about LIBERO's human demonstrations (3D-mouse or keyboard teleoperation) and what each trait becomes:
- smooth, curved paths: the long free moves (to above the object, carrying it to above the target) follow a quadratic
  Bezier curve through a via-point offset sideways from the segment's midpoint, timed by a minimum-jerk profile;
- speed that varies between demonstrations and between segments: a log-normal speed factor per demonstration times
  one per phase;
- idle "no-op" stretches (zero motion, gripper unchanged): at the start and, at random, before a phase;
- overshoot and correct near the grasp and the place: a curved move may end past its goal (along the way it was going),
  and the closed loop then brings the hand back;
- an occasional regrasp: at the grasp pose the fingers close partly, open, the hand lifts a little and comes back down
  before the grasp proper.
Every perturbation changes targets and timing only: each phase still ends with the scripted expert's own proportional
move to its goal (tolerance and step cap unchanged), so demonstrations keep succeeding where the script does. At
diversity 0 every perturbation is off and the actions are the scripted expert's, bit for bit.
"""

from dataclasses import dataclass, replace

import numpy as np

from lerobot_predvla.sims.libero.expert import ScriptedExpert
from lerobot_predvla.sims.libero.expert.motion import CLOSE, DEFAULT_HALF_TURN, DOWN, OPEN, Motion, Skill

STYLES = ("scripted", "teleop")
DEFAULT_STYLE = "scripted"  # every recorded dataset
CURVED_PHASES = ("approach", "carry")  # free moves an operator sweeps through the air; they may also overshoot
REGRASP_PHASE = "descend"  # the move onto the grasp pose
TELEOP_STREAM = 84  # the teleoperator's generator is seeded with (episode seed, TELEOP_STREAM)
MIN_SWEEP_STEPS = 8


@dataclass(frozen=True)
class TeleopParams:
    """The teleoperator model's parameters at diversity 1 (`predvla demos --style teleop --diversity 1`), the committed
    setting; `at(diversity)` scales them. Fixed before any training on teleop demonstrations.

    Args:
        via_offset: Std of a curved segment's via-point offset from the segment's midpoint, as a fraction of the
            segment's length: across the segment in the horizontal plane, plus an upward part half as large (never
            downward). Scaled by the diversity; 0 moves in straight lines, as the script.
        min_curve: Segments shorter than this (m) are never curved: the last centimetres before a goal.
        nominal_speed: The operator's mean hand speed along a curved segment (m per control step at 20 Hz), before
            the speed factors; it sets the segment's duration.
        demo_speed_sd: Std of the log of a demonstration's speed factor (scaled by the diversity).
        segment_speed_sd: Std of the log of a phase's speed factor, on top of the demonstration's (scaled).
        speed_min: Smallest speed factor (product of the two), times the script's speed.
        speed_max: Largest speed factor; an action component stays within [-1, 1] whatever the factor.
        start_idle: Mean length (control steps, Poisson) of the idle stretch before the first motion (scaled).
        phase_idle_prob: Probability of an idle stretch before each phase (scaled, at most 1).
        phase_idle: Mean length (control steps) of such a stretch: 1 + Poisson(phase_idle - 1).
        overshoot_prob: Probability that a curved segment ends past its goal (scaled, at most 1).
        overshoot: Mean distance (m) past the goal, horizontal, along the segment's direction with a sideways part
            of up to a third; drawn uniformly between half and 1.5 times this.
        regrasp_prob: Probability per grasp of a regrasp (scaled, at most 1).
        regrasp_close_steps: Steps the fingers close before the regrasp opens them again.
        regrasp_lift: Height (m) the hand lifts during a regrasp before coming back down.
    """

    via_offset: float = 0.25
    min_curve: float = 0.06
    nominal_speed: float = 0.015
    demo_speed_sd: float = 0.15
    segment_speed_sd: float = 0.15
    speed_min: float = 0.7
    speed_max: float = 1.3
    start_idle: float = 8.0
    phase_idle_prob: float = 0.25
    phase_idle: float = 5.0
    overshoot_prob: float = 0.5
    overshoot: float = 0.02
    regrasp_prob: float = 0.15
    regrasp_close_steps: int = 6
    regrasp_lift: float = 0.03

    def at(self, diversity: float) -> "TeleopParams":
        """These parameters at `diversity` (0: the scripted expert; 1: as committed; above 1: stronger, with the
        probabilities capped at 1)."""
        if not diversity >= 0:
            raise ValueError(f"diversity must be >= 0, got {diversity}")
        return replace(self, via_offset=self.via_offset * diversity, demo_speed_sd=self.demo_speed_sd * diversity,
                       segment_speed_sd=self.segment_speed_sd * diversity, start_idle=self.start_idle * diversity,
                       phase_idle_prob=min(1.0, self.phase_idle_prob * diversity),
                       overshoot_prob=min(1.0, self.overshoot_prob * diversity),
                       regrasp_prob=min(1.0, self.regrasp_prob * diversity))


TELEOP = TeleopParams()  # the committed setting (diversity 1)


def minimum_jerk(tau: float) -> float:
    """The minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5: 0 to 1 with zero velocity and acceleration at
    both ends."""
    tau = min(max(tau, 0.0), 1.0)
    return tau ** 3 * (10 - 15 * tau + 6 * tau ** 2)


def bezier(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, s: float) -> np.ndarray:
    """The quadratic Bezier curve from `p0` to `p2` pulled towards `p1`, at parameter `s` in [0, 1]."""
    return (1 - s) ** 2 * p0 + 2 * (1 - s) * s * p1 + s ** 2 * p2


def across(direction: np.ndarray) -> np.ndarray:
    """Horizontal unit vector perpendicular to `direction` (x if it is vertical)."""
    side = np.array([-direction[1], direction[0], 0.0])
    norm = np.linalg.norm(side)
    return side / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0])


def via_point(start: np.ndarray, end: np.ndarray, offset: float, rng: np.random.Generator) -> np.ndarray:
    """Bezier control point of a curved segment: the midpoint, moved sideways by N(0, offset * length) and up by
    |N(0, offset * length / 2)| (`TeleopParams.via_offset`)."""
    length = float(np.linalg.norm(end - start))
    sideways, up = rng.normal(0.0, offset * length), abs(rng.normal(0.0, offset * length / 2))
    return (start + end) / 2 + sideways * across(end - start) + np.array([0.0, 0.0, up])


def overshoot_vector(start: np.ndarray, end: np.ndarray, mean: float, rng: np.random.Generator) -> np.ndarray:
    """Where past its goal a segment from `start` to `end` ends (relative to the goal): horizontal, along the
    segment's horizontal direction, `mean` * U(0.5, 1.5) long, with a sideways part of up to a third of that."""
    ahead = np.append(end[:2] - start[:2], 0.0)
    ahead = ahead / np.linalg.norm(ahead) if np.linalg.norm(ahead) > 1e-9 else across(np.array([0.0, 1.0, 0.0]))
    length = mean * rng.uniform(0.5, 1.5)
    return length * (ahead + rng.uniform(-1 / 3, 1 / 3) * across(ahead))


class TeleopMotion(Motion):
    """The motion primitives as a teleoperator executes them; `start_operator` draws the demonstration's operator."""

    params: TeleopParams
    rng: np.random.Generator
    demo_speed: float = 1.0
    start_idle: int = 0
    _grip: float = OPEN  # the gripper command of the last action: an idle step keeps it

    def start_operator(self, params: TeleopParams, seed: int) -> None:
        """Draw this demonstration's operator from `seed`: its speed factor and the idle steps before it moves
        (`start_idle`)."""
        self.params = params
        self.rng = np.random.default_rng([seed, TELEOP_STREAM])
        self.demo_speed = 1.0
        if params.demo_speed_sd > 0:
            self.demo_speed = float(np.exp(self.rng.normal(0.0, params.demo_speed_sd)))
            self.speed = float(np.clip(self.demo_speed, params.speed_min, params.speed_max))
        self.start_idle = int(self.rng.poisson(params.start_idle))

    def _action(self, pos: np.ndarray, finger: np.ndarray | None, grip: float, axis: np.ndarray = DOWN,
                max_speed: float = 1.0) -> np.ndarray:
        action = super()._action(pos, finger, grip, axis, max_speed)
        action[:3] = np.clip(action[:3], -1.0, 1.0)  # a speed factor above 1 never leaves the action space
        self._grip = grip
        return action

    def _idle(self, steps: int) -> Skill:
        """`steps` no-op actions: no motion, the gripper as it was."""
        for _ in range(steps):
            yield np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, self._grip])

    def _begin(self, phase: str) -> Skill:
        """What an operator does between phases: maybe an idle stretch, and a new speed for the phase."""
        if not phase:
            return
        p = self.params
        if self.rng.random() < p.phase_idle_prob:
            yield from self._idle(1 + int(self.rng.poisson(max(p.phase_idle - 1, 0.0))))
        if p.segment_speed_sd > 0 or p.demo_speed_sd > 0:
            factor = self.demo_speed * float(np.exp(self.rng.normal(0.0, p.segment_speed_sd)))
            self.speed = float(np.clip(factor, p.speed_min, p.speed_max))

    def _sweep(self, goal, grip: float, max_speed: float, axis: np.ndarray) -> Skill:
        """Track a curved, minimum-jerk reference from the hand to goal()'s position (re-evaluated every step), or
        past it by an overshoot; nothing for a segment shorter than `min_curve`."""
        p = self.params
        start = self.view.eef_pos()
        end, _ = goal()
        length = float(np.linalg.norm(end - start))
        if length < p.min_curve:
            return
        control = via_point(start, end, p.via_offset, self.rng)
        past = overshoot_vector(start, end, p.overshoot, self.rng) if self.rng.random() < p.overshoot_prob \
            else np.zeros(3)
        steps = max(MIN_SWEEP_STEPS, int(np.ceil(length / (p.nominal_speed * self.speed))))
        for k in range(1, steps + 1):
            end, finger = goal()
            yield self._action(bezier(start, control, end + past, minimum_jerk(k / steps)), finger, grip, axis,
                               max_speed)

    def _regrasp(self, goal, tol: float, max_steps: int, max_speed: float, axis: np.ndarray) -> Skill:
        """Close the fingers partly, open them, lift the hand a little, come back down onto goal()."""
        p = self.params
        yield from super()._hold(CLOSE, p.regrasp_close_steps, axis=axis)
        yield from super()._hold(OPEN, p.regrasp_close_steps, axis=axis)
        up = self.view.eef_pos() + [0.0, 0.0, p.regrasp_lift]
        yield from super()._move(lambda: (up, goal()[1]), OPEN, tol=0.01, max_steps=20, axis=axis)
        yield from super()._move(goal, OPEN, tol, max_steps, max_speed, axis)

    def _move(self, goal, grip: float, tol: float = 0.01, max_steps: int = 60, max_speed: float = 1.0,
              axis: np.ndarray = DOWN, phase: str = "") -> Skill:
        yield from self._begin(phase)
        if phase in CURVED_PHASES and self.params.via_offset > 0:
            yield from self._sweep(goal, grip, max_speed, axis)
        yield from super()._move(goal, grip, tol, max_steps, max_speed, axis)  # the closed loop finishes the phase
        if phase == REGRASP_PHASE and self.rng.random() < self.params.regrasp_prob:
            yield from self._regrasp(goal, tol, max_steps, max_speed, axis)

    def _hold(self, grip: float, steps: int, finger: np.ndarray | None = None, axis: np.ndarray = DOWN,
              phase: str = "") -> Skill:
        yield from self._begin(phase)
        yield from super()._hold(grip, steps, finger, axis)


class TeleopExpert(TeleopMotion, ScriptedExpert):
    """The scripted expert's plan executed by the teleoperator model; all randomness from `seed` (the episode's)."""

    def __init__(self, env, params: TeleopParams, seed: int, half_turn: str = DEFAULT_HALF_TURN) -> None:
        super().__init__(env, half_turn=half_turn)
        self.start_operator(params, seed)

    def _run(self) -> Skill:
        yield from self._idle(self.start_idle)
        yield from super()._run()


def make_expert(env, seed: int, half_turn: str = DEFAULT_HALF_TURN, teleop: TeleopParams | None = None):
    """The scripted expert, or with `teleop` (TeleopParams at the demonstration's diversity) the teleoperator model
    seeded by the episode's `seed`."""
    if teleop is None:
        return ScriptedExpert(env, half_turn=half_turn)
    return TeleopExpert(env, teleop, seed, half_turn)
