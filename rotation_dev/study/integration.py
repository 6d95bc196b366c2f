"""
Attitude integrators against exact truth: error against cost over a range of step sizes.

Every method of :func:`rotation_node.kinematics.integrate_angular_velocity`
integrates the body angular velocity of two scenes from ``config/scenes/``
over the scene's duration with ``N`` equal steps:

- ``coning.yaml``: classical coning, the analytic truth of
  :func:`rotation_node.scene.motions.coning_truth`;
- ``tumbling_box.yaml``: a box spinning near its intermediate axis (it flips
  every ~2.6 s), the truth of :func:`rotation_node.scene.motions.motion_truth`
  (a fourth-order Lie-Poisson splitting). Near the separatrix the motion is
  ill-conditioned: a perturbation of round-off size grows by many orders of
  magnitude over the flips, so the truth itself is only known to the level
  at which two evaluations of it on different time grids agree. That level is
  measured (:attr:`SceneResult.truth_resolution`) and errors below it are not
  resolved.

The rate is the truth's, evaluated exactly where each method asks for it
(``omega`` given as a function). Error: the largest geodesic angle between the
integrated and the true orientation over all output times, in radians. Cost:
the time of one ``integrate_angular_velocity`` call, best of ``repeat``, with
the rates computed beforehand (the integrator is timed, not the truth).
"""
import dataclasses
from typing import Tuple

import numpy as np
from rotation_dev.paths import config_path
from rotation_node.conversions import quaternion_distance
from rotation_node.kinematics import integrate_angular_velocity, INTEGRATION_METHODS
from rotation_node.scene.motions import motion_truth
from rotation_node.scene.spec import load_scene

from .measure import best_time

#: Scenes integrated: key -> (scene file under config/scenes/, description).
SCENES = {
    'coning': ('coning.yaml', 'coning motion (analytic truth)'),
    'tumbling_box': ('tumbling_box.yaml', 'tumbling box, torque-free (Lie-Poisson truth)'),
}


@dataclasses.dataclass(frozen=True)
class StepResult:
    """One method at one step count: step (s), largest error (rad), seconds per call."""

    steps: int
    step: float
    error: float
    seconds: float


@dataclasses.dataclass(frozen=True)
class MethodCurve:
    """One method over the step counts; ``rates_per_step`` as counted from its rate calls."""

    method: str
    rates_per_step: int
    points: Tuple[StepResult, ...]


@dataclasses.dataclass(frozen=True)
class SceneResult:
    """
    Every integration method on one scene.

    Attributes
    ----------
    truth_resolution : float
        Largest angle (rad) between the truth evaluated at the finest output
        times and the truth evaluated on a grid four times finer, at the same
        times: how well the truth is known (0 to rounding for closed forms).

    """

    key: str
    title: str
    scene_file: str
    duration: float
    truth_resolution: float
    curves: Tuple[MethodCurve, ...]


class _TruthRate:
    """
    The scene's true body rate as an ``omega(times)`` function, computed once per grid.

    The integrator calls it once per call with the stage times of all steps;
    the same grid in the timed repeats is served from the cache, so the
    timing measures the integrator (and a comparison of the times) alone.
    The truth starts at ``t = 0`` (the torque-free truth integrates from its
    first time), so 0 is prepended to the times and its rate dropped.
    """

    def __init__(self, motion, duration):
        self._motion = motion
        self._duration = duration
        self._times = None
        self._rates = None
        self.times_per_call = 0

    def __call__(self, times):
        if self._times is None or not np.array_equal(times, self._times):
            _, w = motion_truth(self._motion, np.concatenate(([0.0], times)), self._duration)
            self._times, self._rates = times.copy(), w[1:]
        self.times_per_call = len(times)
        return self._rates


def integrate_scene(key, steps, repeat):
    """
    Run every integration method on one scene, over the given step counts.

    Parameters
    ----------
    key : str
        A key of :data:`SCENES`.
    steps : sequence of int
        Numbers of equal steps over the scene's duration.
    repeat : int
        Timed calls per point; the best counts.

    Returns
    -------
    SceneResult
        Every method's error and cost at every step count.

    """
    scene_file, title = SCENES[key]
    scene = load_scene(config_path('scenes', scene_file))
    points = {method: [] for method in INTEGRATION_METHODS}
    rates_per_step = {}
    for n in steps:
        t = np.linspace(0.0, scene.duration, n + 1)
        q_true, _ = motion_truth(scene.motion, t, scene.duration)
        for method in INTEGRATION_METHODS:
            rate = _TruthRate(scene.motion, scene.duration)

            def integrate():
                return integrate_angular_velocity(q_true[0], rate, t, method=method)
            q = integrate()
            rates_per_step[method] = rate.times_per_call // n
            points[method].append(StepResult(n, scene.duration / n,
                                             float(quaternion_distance(q, q_true).max()),
                                             best_time(integrate, repeat)))
    curves = tuple(MethodCurve(method, rates_per_step[method], tuple(points[method]))
                   for method in INTEGRATION_METHODS)
    return SceneResult(key, title, f'config/scenes/{scene_file}', scene.duration,
                       _truth_resolution(scene, max(steps)), curves)


def _truth_resolution(scene, steps):
    """Disagreement (rad) of the truth at ``steps + 1`` times with the truth on a 4x finer grid."""
    fine = np.linspace(0.0, scene.duration, 4 * steps + 1)
    q_fine, _ = motion_truth(scene.motion, fine, scene.duration)
    q_coarse, _ = motion_truth(scene.motion, fine[::4], scene.duration)
    return float(quaternion_distance(q_fine[::4], q_coarse).max())


def integration_study(settings):
    """Run :func:`integrate_scene` on every scene of :data:`SCENES` (steps from ``settings``)."""
    return [integrate_scene(key, settings.integration_steps[key], settings.repeat)
            for key in SCENES]
