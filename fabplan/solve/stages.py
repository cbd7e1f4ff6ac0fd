"""Far targets reached in stages: a continuation of the prescribed angle, Meusnier radius
and handles from where the start is to where they are asked.

`solve_in_stages` runs a solver through the stages `_continuation_stages` plans, each but
the last to a loose tolerance; a handle stage out of reach ends the solve (`Stage`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..net.geometry import intersection_angles
from .constraints import ConstantAngle, ConstantCurvature
from .solver import GuidedProjection, IterationRecord

__all__ = ["Stage", "solve_in_stages", "stopped_at", "STAGE_TOLERANCE", "STAGE_ITERATIONS",
           "CONTINUATION_STEP_DEG", "CONTINUATION_RADIUS_FACTOR", "MAX_STAGES"]


# a prescribed angle this far (degrees) from the start's is reached in stages
CONTINUATION_STEP_DEG = 10.0
# a prescribed Meusnier radius more than this factor from the start's (or less than its
# inverse) is reached in stages, each this factor at most from the one before
CONTINUATION_RADIUS_FACTOR = 1.5
# at most this many stages for the angle and radius together (and 10 for the handles)
MAX_STAGES = 12
# each stage but the last is solved to this tolerance, in at most this many iterations
STAGE_TOLERANCE, STAGE_ITERATIONS = 1e-4, 25


@dataclass
class Stage:
    """One stage of a continuation: what it sets, and how far along the way it is.

    Attributes
    ----------
    apply : sets the stage's targets on the solver.
    kind : "targets" (the prescribed angle and radius), "handles" or "" (a plain solve).
    step, steps : the stage's number (from 1) among the stages of its kind.
    """

    apply: Callable[[], None]
    kind: str = ""
    step: int = 1
    steps: int = 1


def solve_in_stages(solver: GuidedProjection, handle_ids: np.ndarray, targets: np.ndarray,
           progress: Callable[[IterationRecord], None] | None) -> Stage | None:
    """Run the solver; a far target (an angle, a radius or handles far from the start) is
    moved there in stages, each solved to a loose tolerance, the last to the full one.

    Returns None when every stage ran, or the handle stage that could not be solved: the
    stages after it move the handles farther still, so solving them would only spend the
    time of a longer give-up.
    """
    stages = _continuation_stages(solver, handle_ids, targets)
    final = solver.settings
    k, stop = 0, None
    while k < len(stages):
        stages[k].apply()
        last = k == len(stages) - 1
        solver.settings = final if last else replace(
            final, tolerance=max(final.tolerance, STAGE_TOLERANCE),
            max_iterations=min(final.max_iterations, STAGE_ITERATIONS))
        if k:
            solver.restart_soft_terms()
        status = solver.run(callback=progress)
        if status == "converged" or last:
            k += 1
        elif stages[k].kind == "handles":
            stop = stages[k]
            break
        else:
            # a target stage out of reach: the ones between it and the last are farther
            # still, so the last (the real targets) is solved right away
            k = len(stages) - 1
    solver.settings = final
    return stop


def _continuation_stages(solver: GuidedProjection, handle_ids: np.ndarray,
                        targets: np.ndarray) -> list[Stage]:
    """The stages of a solve: the prescribed angle moved from the start's in steps of at
    most `CONTINUATION_STEP_DEG` and the prescribed Meusnier radius in factors of at most
    `CONTINUATION_RADIUS_FACTOR`, together; then the handles moved in steps of at most
    one mean edge."""
    moves: list[tuple[Callable[[float], None], int]] = []   # (set at fraction t, steps)
    angle = next((c for c in solver.constraints
                  if isinstance(c, ConstantAngle) and c.cosine is not None), None)
    if angle is not None and angle.cosine is not None:
        goal = float(np.degrees(np.arccos(np.clip(angle.cosine, -1.0, 1.0))))
        here = float(np.degrees(np.median(intersection_angles(solver.state.X, solver.state.stars))))

        def set_angle(t: float, family: ConstantAngle = angle) -> None:
            family.cosine = float(np.cos(np.radians(here + (goal - here) * t)))

        moves.append((set_angle, int(np.ceil(abs(goal - here) / CONTINUATION_STEP_DEG))))
    radius = next((c for c in solver.constraints if isinstance(c, ConstantCurvature)
                   and c.curvature is not None and c.curvature != 0.0), None)
    if radius is not None and radius.curvature is not None and "sphere" in solver.state.blocks:
        moves.append(_curvature_move(radius, radius.curvature,
                                     float(np.median(2 * solver.variable("sphere")[:, 0]))))
    stages: list[Stage] = []
    count = min(MAX_STAGES, max([1] + [steps for _, steps in moves]))
    if moves and count > 1:
        for i in range(1, count + 1):
            def apply(t: float = i / count) -> None:
                for move, _ in moves:
                    move(t)
            stages.append(Stage(apply, "targets", i, count))
    if handle_ids.size:
        begin = solver.vertices[handle_ids]
        far = float(np.linalg.norm(targets - begin, axis=1).max()) / solver.length_scale
        count = int(min(10, max(1, np.ceil(far))))
        for i in range(1, count + 1):
            def place(t: float = i / count) -> None:
                solver.set_vertices(handle_ids, begin + t * (targets - begin))
            stages.append(Stage(place, "handles", i, count))
    return stages or [Stage(lambda: None)]


def _curvature_move(family: ConstantCurvature, goal: float,
                    here: float) -> tuple[Callable[[float], None], int]:
    """Set the prescribed normal curvature (normalized units) at a fraction of the way from
    the start's median to the goal, and the number of steps the way needs: geometric steps
    (the radius changes by the same factor in each) when both have one sign, else equal
    steps, each at most what a factor `CONTINUATION_RADIUS_FACTOR` takes near the goal."""
    log_factor = np.log(CONTINUATION_RADIUS_FACTOR)
    if here * goal > 0:
        ratio = goal / here
        steps = int(np.ceil(abs(np.log(ratio)) / log_factor - 1e-9))

        def move(t: float) -> None:
            family.curvature = goal if t >= 1 else float(here * ratio ** t)
    else:     # flat, or curved the other way: no geometric path
        steps = int(np.ceil(abs(goal - here) / (abs(goal) * (1 - 1 / CONTINUATION_RADIUS_FACTOR))))

        def move(t: float) -> None:
            family.curvature = goal if t >= 1 else float(here + (goal - here) * t)
    return move, steps


def stopped_at(stage: Stage | None) -> str:
    """Where a handle continuation gave up, for the message (empty when it had one step)."""
    if stage is None or stage.steps < 2:
        return ""
    return (f", at step {stage.step} of {stage.steps} towards them; the steps beyond it "
            "were not tried")
