"""
Time per rotation and error against exact truth, for every method on the same hard inputs.

Each conversion family draws its inputs from :mod:`rotation_dev.hard_cases`
(docs/numerics.md), computes the exact rotation of every input with
:mod:`.reference`, and runs every method of :mod:`.methods` on them:

- time: the inputs tiled to a batch of ``Settings.timing_batch`` rows (below
  the 65536 at which the package splits batches across threads, so every
  method runs on one core), best of ``Settings.repeat`` runs of at least
  10 ms after a warm-up call, divided by the batch size. A method without a
  batch form (transforms3d) is timed as the Python loop it needs, over the
  inputs once;
- error: the outputs of a call on that same batch, for its first rows (the
  inputs themselves), each turned into its exact rotation and compared with the
  truth by the geodesic angle, in eps (2**-52). A NaN/Inf output, or an
  input the method rejects, is a failure; worst and median errors are over
  the other samples.

A method that rejects a whole batch (scipy raises for one bad quaternion) is
re-run sample by sample for its errors and has no time on that batch.
"""
import dataclasses
import timeit
from typing import Callable, Dict, Optional, Tuple
import warnings

import numpy as np
from rotation_dev.hard_cases import (
    hard_matrices, hard_quaternions, hard_rotation_vectors, near_gimbal_lock_angles,
    noisy_matrices)
from rotation_node import conversions as rc

from . import methods, reference

#: A method is exact on a family when its worst error is at most this many eps.
EXACT_EPS = 8.0
#: Noise levels of ``R + sigma N`` (docs/numerics.md: 1e-16 to 1e-1).
NOISE_SIGMAS = (1e-16, 1e-13, 1e-10, 1e-7, 1e-4, 1e-2, 1e-1)
#: The noise level whose timing is reported for the noisy matrices.
NOISE_TIMING_SIGMA = 1e-4
#: Shortest timed run (s); short calls are repeated within a run to reach it.
MIN_RUN_SECONDS = 0.01
#: Euler conventions shown one by one: ROS roll-pitch-yaw, its intrinsic twin, a
#: second Tait-Bryan, and proper Euler in both kinds.
FEATURED_SEQUENCES = ('xyz', 'ZYX', 'XYZ', 'zxz', 'ZYZ')


@dataclasses.dataclass(frozen=True)
class Settings:
    """
    Sizes of one run of the study.

    Attributes
    ----------
    samples : int
        Hard matrices and hard quaternions per family.
    noisy_samples : int
        Noisy matrices per noise level.
    euler_samples : int
        Near-gimbal-lock quaternions per Euler convention.
    euler_sequences : tuple of str
        Conventions measured (every method on each that it supports).
    float32_samples : int
        Inputs per function of the float32 comparison.
    timing_batch : int
        Rows per timed call (inputs tiled).
    repeat : int
        Timed runs; the best counts.
    integration_steps : dict
        Step counts per motion of :mod:`.integration`.
    seed : int
        Seed of every input draw.

    """

    samples: int
    noisy_samples: int
    euler_samples: int
    euler_sequences: Tuple[str, ...]
    float32_samples: int
    timing_batch: int
    repeat: int
    integration_steps: Dict[str, Tuple[int, ...]]
    seed: int = 20260707


QUICK = Settings(samples=256, noisy_samples=32, euler_samples=48,
                 euler_sequences=FEATURED_SEQUENCES, float32_samples=96, timing_batch=4096,
                 repeat=3, integration_steps={'coning': (25, 100, 400, 1600),
                                              'tumbling_box': (250, 1000, 4000)})
FULL = Settings(samples=4096, noisy_samples=256, euler_samples=512,
                euler_sequences=rc.SEQUENCES, float32_samples=512, timing_batch=32768,
                repeat=7, integration_steps={
                    'coning': (25, 50, 100, 200, 400, 800, 1600, 3200, 6400),
                    'tumbling_box': (250, 500, 1000, 2000, 4000, 8000, 16000, 32000)})


@dataclasses.dataclass(frozen=True)
class ErrorSummary:
    """
    Errors of one method on one set of inputs, in eps (2**-52).

    Attributes
    ----------
    worst, median : float
        Over the samples that did not fail; NaN if all failed.
    failures : int
        Samples with a NaN/Inf output or rejected by the method.
    samples : int
        Inputs measured.

    """

    worst: float
    median: float
    failures: int
    samples: int

    @classmethod
    def of(cls, errors):
        """Summarise errors in eps (NaN marks a failure)."""
        ok = errors[np.isfinite(errors)]
        worst, median = (ok.max(), np.median(ok)) if ok.size else (np.nan, np.nan)
        return cls(float(worst), float(median), int(errors.size - ok.size), int(errors.size))

    def within(self, bound=EXACT_EPS):
        """Return whether every sample succeeded with an error of at most ``bound`` eps."""
        return self.failures == 0 and self.worst <= bound


@dataclasses.dataclass(frozen=True)
class CaseResult:
    """One method on one set of inputs: time per rotation (ns, None if untimed) and errors."""

    time_ns: Optional[float]
    errors: ErrorSummary


@dataclasses.dataclass(frozen=True)
class MethodResult:
    """One method on every input set of its family (a set it does not support is absent)."""

    method: methods.Method
    cases: Dict[str, CaseResult]


@dataclasses.dataclass(frozen=True)
class FamilyResult:
    """
    One conversion family: every method on every input set.

    Attributes
    ----------
    key : str
        Short identifier (``'matrix'``, ``'noisy'``, ``'rotation_vector'``, ``'euler'``).
    title : str
        Section title.
    inputs : str
        What the inputs are and how many.
    cases : tuple of str
        Names of the input sets (columns of the table).
    timed_case : str
        The input set whose time per rotation is shown and plotted.
    rows : tuple of MethodResult
        One per method, in the order of :mod:`.methods`.

    """

    key: str
    title: str
    inputs: str
    cases: Tuple[str, ...]
    timed_case: str
    rows: Tuple[MethodResult, ...]

    def worst(self, row, cases=None):
        """Return the worst error (eps) and failures of ``row`` over ``cases`` (default all)."""
        summaries = [row.cases[c].errors for c in (cases or self.cases) if c in row.cases]
        worst = max((s.worst for s in summaries if np.isfinite(s.worst)), default=np.nan)
        return worst, sum(s.failures for s in summaries)

    def exact(self, row):
        """Return whether ``row`` is within :data:`EXACT_EPS`, without failure, everywhere."""
        return all(c.errors.within() for c in row.cases.values())

    def fastest_exact(self):
        """Return the fastest row (on ``timed_case``) exact on every input set, or None."""
        timed = [r for r in self.rows if self.timed_case in r.cases
                 and r.cases[self.timed_case].time_ns is not None and self.exact(r)]
        return min(timed, key=lambda r: r.cases[self.timed_case].time_ns, default=None)


def best_time(call, repeat):
    """
    Return the seconds per call: the best of ``repeat`` timed runs, after a warm-up call.

    Each run makes enough calls to last at least :data:`MIN_RUN_SECONDS`, so
    that short calls are not lost in timer resolution and scheduling jitter.
    """
    call()
    number = max(1, int(MIN_RUN_SECONDS / max(timeit.timeit(call, number=1), 1e-9)))
    return min(timeit.repeat(call, number=number, repeat=repeat)) / number


def _sample_by_sample(function, inputs, width):
    """Run the method row by row; NaN rows where it rejects the sample."""
    outputs = np.full((len(inputs),) + width, np.nan)
    for index in range(len(inputs)):
        try:
            outputs[index] = function(inputs[index:index + 1])[0]
        except ValueError:
            pass
    return outputs


def run_case(method_function, inputs, width, settings, *, batch=True, timed=True):
    """
    Run one method on one input set: outputs for the inputs, and time per rotation.

    Parameters
    ----------
    method_function : callable
        Batch in, batch out.
    inputs : ndarray, shape (n, ...)
        The input set.
    width : tuple of int
        Trailing shape of one output (for the rows of failed samples).
    settings : Settings
        Timing batch and repeats.
    batch : bool
        Time on the tiled batch (True) or on the inputs once (a Python loop).
    timed : bool
        Whether to time at all.

    Returns
    -------
    outputs : ndarray, shape (n,) + width
    time_ns : float or None
        None when untimed or when the method rejects the batch.

    """
    n = len(inputs)
    size = max(n, settings.timing_batch) if batch else n
    tiled = np.resize(inputs, (size,) + inputs.shape[1:])    # repeats the inputs in order
    # Peers warn about what the study measures (scipy: "Gimbal lock detected").
    with np.errstate(all='ignore'), warnings.catch_warnings():
        warnings.simplefilter('ignore')
        try:
            outputs = method_function(tiled)[:n]
        except ValueError:
            return _sample_by_sample(method_function, inputs, width), None
        if not timed:
            return outputs, None
        seconds = best_time(lambda: method_function(tiled), settings.repeat)
    return outputs, seconds / size * 1e9


def _measure(method_function, inputs, truths, to_reference, width, settings, *, batch=True,
             timed=True):
    outputs, time_ns = run_case(method_function, inputs, width, settings, batch=batch,
                                timed=timed)
    errors = reference.errors_in_eps(to_reference(outputs), truths)
    return CaseResult(time_ns, ErrorSummary.of(errors))


# ------------------------------------------------------------ the families

def matrix_to_quaternion(settings):
    """Measure every matrix -> quaternion method on the hard rotation matrices."""
    rng = np.random.default_rng([settings.seed, 1])
    m = hard_matrices(rng, settings.samples)
    truths = reference.quaternions_from_nearest_rotation(m)
    case = 'hard matrices'
    rows = tuple(MethodResult(method, {case: _measure(
        method.function, m, truths, reference.quaternions, (4,), settings)})
        for method in methods.MATRIX_TO_QUATERNION)
    return FamilyResult(
        'matrix', 'Matrix to quaternion',
        f'{len(m)} rotation matrices (`hard_cases.hard_matrices`): rotations by 0, '
        '10^U(-16,-1), pi - 10^U(-16,-1) and pi, from quaternions of every hard scale, plus '
        'diag(1,-1,-1) and its permutations. Truth: the nearest rotation of each float '
        'matrix, 40 digits.', (case,), case, rows)


def _sigma_case(sigma):
    return f'sigma {sigma:.0e}'


def noisy_matrix_to_quaternion(settings):
    """Measure every matrix -> quaternion method on ``R + sigma N`` (nearest rotation as truth)."""
    rng = np.random.default_rng([settings.seed, 2])
    inputs = {_sigma_case(s): noisy_matrices(rng, settings.noisy_samples, s)[0]
              for s in NOISE_SIGMAS}
    truths = {case: reference.quaternions_from_nearest_rotation(m) for case, m in inputs.items()}
    timed_case = _sigma_case(NOISE_TIMING_SIGMA)
    rows = tuple(MethodResult(method, {case: _measure(
        method.function, m, truths[case], reference.quaternions, (4,), settings,
        timed=case == timed_case) for case, m in inputs.items()})
        for method in methods.MATRIX_TO_QUATERNION)
    return FamilyResult(
        'noisy', 'Matrix to quaternion, noisy matrices R + sigma N',
        f'{settings.noisy_samples} matrices per noise level (`hard_cases.noisy_matrices`): '
        'random rotations plus sigma times a standard normal matrix. Error: distance from '
        'the rotation nearest to the noisy matrix (Frobenius norm, 40 digits), the answer '
        'a user of a noisy matrix wants.', tuple(inputs), timed_case, rows)


def quaternion_to_rotation_vector(settings):
    """Measure every quaternion -> rotation vector method on unit and scaled hard quaternions."""
    rng = np.random.default_rng([settings.seed, 3])
    unit = rc.quaternion_from_rotation_vector(hard_rotation_vectors(rng, settings.samples))
    inputs = {'unit quaternions': unit,
              'hard quaternion corpus': hard_quaternions(rng, settings.samples)}
    truths = {case: reference.quaternions(q) for case, q in inputs.items()}
    rows = tuple(MethodResult(method, {case: _measure(
        method.function, q, truths[case], reference.quaternions_from_rotation_vectors, (3,),
        settings, timed=case == 'unit quaternions') for case, q in inputs.items()})
        for method in methods.QUATERNION_TO_ROTATION_VECTOR)
    return FamilyResult(
        'rotation_vector', 'Quaternion to rotation vector (angle and axis)',
        f'{settings.samples} unit quaternions of rotations by 0, 10^U(-16,-1), '
        'pi - 10^U(-16,-1), pi and uniform angles (`hard_cases.hard_rotation_vectors`); '
        f'and {settings.samples} of the hard quaternion corpus (`hard_cases.hard_quaternions`:'
        ' the same angles scaled by 1e-160, 1e+160, 1 +- 1e-6 and -1, and w = 0 exactly). '
        'Truth: the rotation of each float quaternion, 40 digits.',
        tuple(inputs), 'unit quaternions', rows)


def quaternion_to_euler(settings):
    """Measure every quaternion -> Euler method near gimbal lock, in each of its conventions."""
    rng = np.random.default_rng([settings.seed, 4])
    inputs, truths = {}, {}
    for seq in settings.euler_sequences:
        angles = near_gimbal_lock_angles(rng, settings.euler_samples, seq)
        inputs[seq] = rc.quaternion_from_euler(angles, seq)
        truths[seq] = reference.quaternions(inputs[seq])
    rows = []
    for method in methods.QUATERNION_TO_EULER:
        cases = {}
        for seq in settings.euler_sequences:
            if method.sequences is None or seq in method.sequences:
                cases[seq] = _measure(
                    lambda q, seq=seq: method.function(q, seq), inputs[seq], truths[seq],
                    lambda a, seq=seq: reference.quaternions_from_euler(a, seq), (3,), settings,
                    batch=method.batch)
        rows.append(MethodResult(method, cases))
    return FamilyResult(
        'euler', 'Quaternion to Euler angles near gimbal lock',
        f'{settings.euler_samples} quaternions per convention '
        '(`hard_cases.near_gimbal_lock_angles`): middle angle at its singular value +- '
        '10^U(-16,-2), exactly at it for every eighth, outer angles uniform. Errors compare '
        'rotations (the exact rotation of the output angles against that of the float input '
        'quaternion), never angles, which are not unique at gimbal lock.',
        tuple(settings.euler_sequences), methods.ROS_RPY, tuple(rows))


# ------------------------------------------------------------ float32 pipeline

@dataclasses.dataclass(frozen=True)
class Float32Result:
    """
    One package function, float64 against a float32 pipeline.

    Attributes
    ----------
    function : str
        The call measured.
    inputs : str
        Which hard cases.
    float64 : ErrorSummary
        float64 inputs and outputs, against the exact rotation of the input.
    float32_output : ErrorSummary
        Inputs rounded to float32, outputs rounded to float32, against the
        exact rotation of the float32 input: what the computation adds.
    float32_end_to_end : ErrorSummary
        The same outputs against the exact rotation of the float64 input:
        what a float32 pipeline loses in all.
    time64_ns, time32_ns : float
        Time per rotation with float64 and with float32 input arrays.

    """

    function: str
    inputs: str
    float64: ErrorSummary
    float32_output: ErrorSummary
    float32_end_to_end: ErrorSummary
    time64_ns: float
    time32_ns: float


@dataclasses.dataclass(frozen=True)
class _Float32Case:
    label: str
    function: Callable
    inputs: np.ndarray
    description: str
    width: Tuple[int, ...]
    input_truth: Callable     # float inputs -> reference quaternions
    output_truth: Callable    # float outputs -> reference quaternions


def _ros_rpy_truth(angles):
    return reference.quaternions_from_euler(angles, methods.ROS_RPY)


def _float32_cases(settings):
    rng = np.random.default_rng([settings.seed, 5])
    n = settings.float32_samples
    rpy = methods.ROS_RPY
    gimbal = near_gimbal_lock_angles(rng, n, rpy)
    return (
        _Float32Case('quaternion_from_matrix', rc.quaternion_from_matrix,
                     hard_matrices(rng, n), 'hard matrices', (4,),
                     reference.quaternions_from_nearest_rotation, reference.quaternions),
        _Float32Case('rotation_vector_from_quaternion', rc.rotation_vector_from_quaternion,
                     rc.quaternion_from_rotation_vector(hard_rotation_vectors(rng, n)),
                     'unit quaternions', (3,), reference.quaternions,
                     reference.quaternions_from_rotation_vectors),
        _Float32Case('quaternion_from_rotation_vector', rc.quaternion_from_rotation_vector,
                     hard_rotation_vectors(rng, n), 'hard rotation vectors', (4,),
                     reference.quaternions_from_rotation_vectors, reference.quaternions),
        _Float32Case(f"euler_from_quaternion(q, '{rpy}')",
                     lambda q: rc.euler_from_quaternion(q, rpy),
                     rc.quaternion_from_euler(gimbal, rpy), 'near gimbal lock', (3,),
                     reference.quaternions, _ros_rpy_truth),
        _Float32Case(f"quaternion_from_euler(a, '{rpy}')",
                     lambda a: rc.quaternion_from_euler(a, rpy), gimbal, 'near gimbal lock',
                     (4,), _ros_rpy_truth, reference.quaternions),
    )


def float32_pipeline(settings):
    """Measure the package's functions in float64 and in a float32 pipeline."""
    results = []
    for case in _float32_cases(settings):
        x64 = case.inputs
        x32 = x64.astype(np.float32)
        y64, time64 = run_case(case.function, x64, case.width, settings)
        y32, time32 = run_case(case.function, x32, case.width, settings)
        truth64, truth32 = case.input_truth(x64), case.input_truth(x32)
        outputs32 = case.output_truth(y32.astype(np.float32))
        results.append(Float32Result(
            case.label, case.description,
            ErrorSummary.of(reference.errors_in_eps(case.output_truth(y64), truth64)),
            ErrorSummary.of(reference.errors_in_eps(outputs32, truth32)),
            ErrorSummary.of(reference.errors_in_eps(outputs32, truth64)),
            time64, time32))
    return results
