"""Inverse kinematics: damped least squares on pinocchio's frame Jacobians, within limits.

pinocchio ships no IK solver; its documentation's closed-loop IK (CLIK) is the baseline:
the error is ``log6(tip^-1 * target)`` (a twist in the tip's frame), and each step solves
``J dq = -err`` by damped least squares with ``J = -Jlog6 @ J_local``. What this adds:

- the variables are the ACTUATED joints (mimics follow, `MotionModel`);
- each step is clamped to the joint limits (a projection onto the box), the step's size
  bounded so one step cannot jump across a limit's far side;
- a run that stalls (at a limit, at a singularity) restarts from a random configuration
  within the limits, ``restarts`` times at most, the seed (the current state) first;
- an optional collision check (`CollisionWorld`) of each converged solution: one touching
  an obstacle is set aside and the search goes on.

When no attempt succeeds, `IkResult.failure` says why, in this order:

- ``collision``: solutions reach the target but touch an obstacle (link and obstacle named);
- ``joint_limit``: the same search without limits reaches it, outside the named joints'
  limits;
- ``unreachable``: not even without limits.

with the best residual found (mm, degrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator, Mapping, Optional

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from bridge.motion.errors import MotionInputError
from bridge.motion.model import MotionModel
from protocol.conversions import metres_to_mm, validate_matrix

if TYPE_CHECKING:
    from bridge.motion.collisions import CollisionWorld, Contact

__all__ = ["IkFailure", "IkOptions", "IkResult", "solve_ik", "target_pose"]

F64 = npt.NDArray[np.float64]

UNREACHABLE = "unreachable"
JOINT_LIMIT = "joint_limit"
COLLISION = "collision"


@dataclass(frozen=True)
class IkOptions:
    """How hard the solver tries. Tolerances are far below the 0.1 mm / 0.1 deg a client
    asks for, so a converged solution is exact for any display or instrument."""

    position_tolerance_m: float = 1e-6
    rotation_tolerance_rad: float = 1e-5
    iterations: int = 100  # per attempt
    restarts: int = 60
    stall_iterations: int = 12  # without a 1 % gain: restart elsewhere
    damping: float = 0.5  # times the squared error
    max_step: float = 0.5  # rad (or m) per joint per iteration
    random_seed: int = 0  # the restarts' generator: the same request, the same answer


@dataclass(frozen=True)
class IkFailure:
    """Why no solution: ``reason`` (unreachable, joint_limit, collision), what it concerns
    (the joints past their limits; the link and the obstacle in contact), and a sentence."""

    reason: str
    text: str
    joints: tuple[str, ...] = ()
    link: str = ""
    obstacle: str = ""

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {"reason": self.reason, "text": self.text}
        if self.joints:
            out["joints"] = list(self.joints)
        if self.link:
            out["link"] = self.link
            out["obstacle"] = self.obstacle
        return out


@dataclass(frozen=True)
class IkResult:
    """A solution (``positions`` of the actuated joints) or a ``failure``; the residual of
    the best attempt either way: position in mm, rotation in degrees."""

    positions: dict[str, float]
    residual_mm: float
    residual_deg: float
    iterations: int
    attempts: int
    failure: Optional[IkFailure] = None
    theta: F64 = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def ok(self) -> bool:
        return self.failure is None


def target_pose(matrix_m: npt.ArrayLike, field: str = "target") -> pin.SE3:
    """A 4x4 target (metres) as an SE3: refused unless finite and rigid
    (`protocol.conversions.validate_matrix`); its rotation is then made exactly orthonormal
    (the nearest rotation), since a client's float32 matrix is orthonormal only to ~1e-7."""
    try:
        m = validate_matrix(matrix_m, field=field)
    except Exception as error:  # ConversionError: re-raised as this package's input error
        raise MotionInputError(getattr(error, "field", field),
                               getattr(error, "expected", "a rigid 4x4 transform"),
                               getattr(error, "got", str(error))) from None
    u, _, vt = np.linalg.svd(m[:3, :3])
    rotation = u @ vt
    return pin.SE3(rotation, np.ascontiguousarray(m[:3, 3]))


def _residual(current: pin.SE3, target: pin.SE3) -> tuple[float, float]:
    """(position error in metres, rotation error in radians) between two poses."""
    position = float(np.linalg.norm(current.translation - target.translation))
    rotation = float(np.linalg.norm(pin.log3(current.rotation.T @ target.rotation)))
    return position, rotation


@dataclass
class _Attempt:
    theta: F64
    position_m: float
    rotation_rad: float
    iterations: int
    converged: bool


def _descend(model: MotionModel, frame: int, target: pin.SE3, theta: F64, options: IkOptions,
             limited: bool, moving: npt.NDArray[np.bool_]) -> _Attempt:
    """One damped least-squares run from ``theta``, moving the joints ``moving`` only; stops
    converged, stalled or at the iteration bound."""
    lower = model.lower if limited else np.full_like(model.lower, -math.inf)
    upper = model.upper if limited else np.full_like(model.upper, math.inf)
    lower = np.where(moving, lower, theta)
    upper = np.where(moving, upper, theta)
    theta = np.clip(theta, lower, upper)
    best = math.inf
    since_best = 0
    position = rotation = math.inf
    for iteration in range(1, options.iterations + 1):
        model.update(theta)
        current = model.pose(frame)
        position, rotation = _residual(current, target)
        if (position <= options.position_tolerance_m
                and rotation <= options.rotation_tolerance_rad):
            return _Attempt(theta, position, rotation, iteration, True)
        size = position + rotation
        if size < best * 0.99:
            best, since_best = size, 0
        else:
            since_best += 1
            if since_best >= options.stall_iterations:  # stalled: at a limit or a singularity
                break
        error_to_target = current.actInv(target)
        err = pin.log6(error_to_target).vector
        jac = -pin.Jlog6(error_to_target.inverse()) @ model.jacobian(theta, frame)
        # Damping that shrinks with the error (Sugihara's Levenberg-Marquardt rule): far
        # from the target it keeps steps sane near singularities, close to it the step is
        # Newton's, so a near-singular wrist still converges.
        damping = options.damping * float(err @ err) + 1e-12
        step = -jac.T @ np.linalg.solve(jac @ jac.T + damping * np.eye(6), err)
        largest = float(np.max(np.abs(step))) if len(step) else 0.0
        if largest > options.max_step:
            step *= options.max_step / largest
        theta = np.clip(theta + step, lower, upper)
    return _Attempt(theta, position, rotation, options.iterations, False)


def _attempts(model: MotionModel, frame: int, target: pin.SE3, seed: F64, options: IkOptions,
              limited: bool) -> Iterator[_Attempt]:
    """The seed's run, then runs from random configurations within the limits."""
    rng = np.random.default_rng(options.random_seed)
    moving = model.moves_frame(frame)
    best = _descend(model, frame, target, seed, options, limited, moving)
    yield best
    for restart in range(options.restarts):
        if restart % 2:  # near the best so far: a target close to a limit has a small basin
            start = np.clip(best.theta + rng.normal(0.0, 0.3, len(seed)),
                            model.lower, model.upper)
        else:
            start = model.random_theta(rng)
        attempt = _descend(model, frame, target, np.where(moving, start, seed), options,
                           limited, moving)
        if attempt.position_m + attempt.rotation_rad < best.position_m + best.rotation_rad:
            best = attempt
        yield attempt


def solve_ik(model: MotionModel, target_m: npt.ArrayLike, tip: str,
             seed: Optional[Mapping[str, float]] = None, *,
             world: Optional[CollisionWorld] = None,
             options: IkOptions = IkOptions()) -> IkResult:
    """Joint positions putting link ``tip`` at ``target_m`` (4x4, metres, in the robot's
    root link frame), starting from ``seed`` (the current joint state; joints not given at
    0), within limits, and clear of ``world``'s obstacles when given.

    Raises `MotionInputError` for a target that is not a finite rigid transform or a tip
    that is not a link; an unreachable target is a result with ``failure`` set."""
    frame = model.frame_id(tip)
    target = target_pose(target_m)
    start = model.theta_of(seed or {})
    best: Optional[_Attempt] = None
    collided: Optional[tuple[_Attempt, Contact]] = None
    attempts = iterations = 0
    for attempt in _attempts(model, frame, target, start, options, True):
        attempts += 1
        iterations += attempt.iterations
        if best is None or (attempt.position_m + attempt.rotation_rad
                            < best.position_m + best.rotation_rad):
            best = attempt
        if not attempt.converged:
            continue
        contact = world.first_contact(attempt.theta) if world is not None else None
        if contact is None:
            return _result(model, attempt, attempts, iterations)
        if collided is None:
            collided = (attempt, contact)
    assert best is not None
    if collided is not None:
        attempt, contact = collided
        failure = IkFailure(COLLISION, f"every solution found puts link {contact.link!r} "
                            f"in contact with obstacle {contact.obstacle!r}",
                            link=contact.link, obstacle=contact.obstacle)
        return _result(model, attempt, attempts, iterations, failure)
    failure = _why_not(model, frame, target, start, options)
    return _result(model, best, attempts, iterations, failure)


def _why_not(model: MotionModel, frame: int, target: pin.SE3, start: F64,
             options: IkOptions) -> IkFailure:
    """No solution within limits: does one exist beyond them?"""
    relaxed = IkOptions(position_tolerance_m=options.position_tolerance_m,
                        rotation_tolerance_rad=options.rotation_tolerance_rad,
                        iterations=options.iterations, restarts=min(options.restarts, 10),
                        stall_iterations=options.stall_iterations,
                        damping=options.damping, max_step=options.max_step,
                        random_seed=options.random_seed)
    for attempt in _attempts(model, frame, target, start, relaxed, False):
        if attempt.converged:
            outside = tuple(name for name, value, low, high in
                            zip(model.joint_names, attempt.theta, model.lower, model.upper)
                            if value < low - 1e-9 or value > high + 1e-9)
            named = ", ".join(outside)
            return IkFailure(JOINT_LIMIT, f"the target is reached only beyond the limits "
                             f"of joint(s) {named}", joints=outside)
    return IkFailure(UNREACHABLE, "no joint positions reach the target (out of reach or "
                     "an orientation the arm cannot take there)")


def _result(model: MotionModel, attempt: _Attempt, attempts: int, iterations: int,
            failure: Optional[IkFailure] = None) -> IkResult:
    return IkResult(positions=model.positions_of(attempt.theta),
                    residual_mm=float(metres_to_mm(attempt.position_m)),
                    residual_deg=math.degrees(attempt.rotation_rad),
                    iterations=iterations, attempts=attempts, failure=failure,
                    theta=attempt.theta)
