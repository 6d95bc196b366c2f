"""
Two streams compared: accuracy of the time offset, world alignment and mounting, and their cost.

Synthetic truth (:mod:`rotation_dev.two_streams`: a random smooth motion about
all axes, a 100 Hz reference and a 200 Hz estimate, random ``W`` and ``M``,
``dt = 37.3 ms``, the same noise on both) over noise levels and record
lengths, several seeds each. For each: the errors of the estimated ``dt``,
``W`` and ``M``, the root mean square error angle after the estimated
alignment against the one after the true alignment, and the wall time of
:func:`rotation_node.comparison.estimate_time_offset` and of
:func:`rotation_node.comparison.estimate_alignment` (both rotations and the
offset).

:func:`measure` returns the rows, :func:`comparison_markdown` the section of
``accuracy.md`` and :func:`comparison_png` its plot.
"""
from dataclasses import dataclass
import io
import os
import time
from typing import List, Sequence

import numpy as np
from rotation_dev.two_streams import two_streams
from rotation_node import comparison
from scipy.spatial.transform import Rotation

NOISE_DEG = (0.1, 0.3, 1.0, 3.0)
DURATIONS_S = (10.0, 30.0, 60.0)
SEEDS = (1, 2, 3)
QUICK_NOISE_DEG = (0.3, 1.0)
QUICK_DURATIONS_S = (10.0,)
QUICK_SEEDS = (1,)
TIME_OFFSET_S = 0.0373
_MEASURED = ('', (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class ComparisonRow:
    """
    One noise level and record length: the worst over the seeds, the median time.

    Attributes
    ----------
    noise_deg : float
        Root mean square noise angle of each stream.
    duration_s : float
        Length of the reference record.
    time_offset_error_s, world_error_deg, mounting_error_deg : float
        Largest error of the estimate over the seeds.
    time_offset_std_s : float
        The largest standard deviation the estimate reported.
    rmse_ratio : float
        The error angle's root mean square after the estimated alignment over the one after
        the true alignment, furthest from 1 over the seeds.
    offset_seconds, alignment_seconds : float
        Median wall time of one time offset estimate and one full alignment.

    """

    noise_deg: float
    duration_s: float
    time_offset_error_s: float
    time_offset_std_s: float
    world_error_deg: float
    mounting_error_deg: float
    rmse_ratio: float
    offset_seconds: float
    alignment_seconds: float


def _angle_deg(p, q):
    return float(np.degrees((Rotation.from_quat(p).inv() * Rotation.from_quat(q)).magnitude()))


def _rmse(streams, dt, world, mounting):
    series = comparison.aligned_series(streams.t_ref, streams.q_ref, streams.t_est,
                                       streams.q_est, time_offset=dt, world=world,
                                       mounting=mounting)
    return comparison.error_statistics(series.errors).rmse


def _case(noise, duration, seed):
    streams = two_streams(seed, duration=duration, noise_ref_deg=noise, noise_est_deg=noise,
                          time_offset=TIME_OFFSET_S)
    start = time.perf_counter()
    comparison.estimate_time_offset(streams.t_ref, streams.q_ref, streams.t_est, streams.q_est)
    offset_seconds = time.perf_counter() - start
    start = time.perf_counter()
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est)
    alignment_seconds = time.perf_counter() - start
    ratio = (_rmse(streams, found.time_offset, found.world, found.mounting)
             / _rmse(streams, TIME_OFFSET_S, streams.world, streams.mounting))
    return (abs(found.time_offset - TIME_OFFSET_S), found.time_offset_std,
            _angle_deg(found.world, streams.world), _angle_deg(found.mounting, streams.mounting),
            ratio, offset_seconds, alignment_seconds)


def measure(quick: bool = False) -> List[ComparisonRow]:
    """Return one row per noise level and record length."""
    global _MEASURED   # when and under what load, for the section's text
    _MEASURED = (time.strftime('%Y-%m-%d %H:%M', time.gmtime()), os.getloadavg())
    _case(1.0, 5.0, 0)   # compiles what the library compiles on first use: not timed
    rows = []
    for duration in (QUICK_DURATIONS_S if quick else DURATIONS_S):
        for noise in (QUICK_NOISE_DEG if quick else NOISE_DEG):
            cases = np.array([_case(noise, duration, seed)
                              for seed in (QUICK_SEEDS if quick else SEEDS)])
            ratio = cases[np.argmax(np.abs(cases[:, 4] - 1.0)), 4]
            rows.append(ComparisonRow(
                noise, duration, float(cases[:, 0].max()), float(cases[:, 1].max()),
                float(cases[:, 2].max()), float(cases[:, 3].max()), float(ratio),
                float(np.median(cases[:, 5])), float(np.median(cases[:, 6]))))
    return rows


def comparison_markdown(rows: Sequence[ComparisonRow], *, heading: str = '##') -> str:
    """Return the section of ``accuracy.md``."""
    seeds = len(SEEDS) if len({r.duration_s for r in rows}) > 1 else len(QUICK_SEEDS)
    lines = [
        f'{heading} Two streams: time offset, world alignment and mounting',
        '',
        'Synthetic truth (`rotation_dev/two_streams.py`): a random smooth motion about all '
        'axes, a 100 Hz reference and a 200 Hz estimate of it with random world alignment W '
        f'and mounting M, time offset {TIME_OFFSET_S * 1e3:.1f} ms, and the same Gaussian '
        f'noise on both (the root mean square angle below); {seeds} seed(s) per row, the '
        'worst error over them and the median time. `rmse ratio`: the root mean square error '
        'angle after the estimated alignment over that after the true one. Times are wall '
        'times of one call on this machine (`estimate_time_offset` alone, and '
        '`estimate_alignment` of dt, W and M together), measured on {} UTC at load average '
        '{:.2f}, {:.2f}, {:.2f}.'.format(_MEASURED[0], *_MEASURED[1]),
        '',
        '![errors of dt, W and M against noise and record length](compare_accuracy.png)',
        '',
        '| noise (deg) | record (s) | dt error (ms) | dt std (ms) | W error (deg) '
        '| M error (deg) | rmse ratio | time: dt (s) | time: dt, W, M (s) |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for r in rows:
        lines.append(
            f'| {r.noise_deg:g} | {r.duration_s:g} | {r.time_offset_error_s * 1e3:.3f} '
            f'| {r.time_offset_std_s * 1e3:.3f} | {r.world_error_deg:.4f} '
            f'| {r.mounting_error_deg:.4f} | {r.rmse_ratio:.4f} | {r.offset_seconds:.2f} '
            f'| {r.alignment_seconds:.2f} |')
    headline = [r for r in rows if r.noise_deg == 0.3 and r.duration_s == 60.0]
    if headline:
        r = headline[0]
        lines += ['', f'**Verdict:** on 60 s at 0.3 deg the time offset is within '
                      f'{r.time_offset_error_s * 1e3:.3f} ms (target 1 ms), W and M within '
                      f'{max(r.world_error_deg, r.mounting_error_deg):.4f} deg (target 0.1), '
                      f'the error statistics within {abs(r.rmse_ratio - 1) * 100:.2f} % of '
                      'those at the true alignment (target 5 %). The errors grow with the '
                      'noise; those of W and M fall with the record length. The rows share '
                      'their seeds (the same motions, and noise draws scaled to each level), '
                      'so their worst cases are not independent samples.']
    return '\n'.join(lines) + '\n'


def comparison_png(rows: Sequence[ComparisonRow]) -> bytes:
    """Return the plot: errors of dt and of W, M against noise, one line per record length."""
    from matplotlib.figure import Figure
    figure = Figure(figsize=(10, 3.8), layout='constrained')
    left, right = figure.subplots(1, 2)
    for duration in sorted({r.duration_s for r in rows}):
        chosen = [r for r in rows if r.duration_s == duration]
        noise = [r.noise_deg for r in chosen]
        left.loglog(noise, [max(r.time_offset_error_s * 1e3, 1e-4) for r in chosen], 'o-',
                    label=f'{duration:g} s')
        right.loglog(noise, [max(r.world_error_deg, r.mounting_error_deg, 1e-5)
                             for r in chosen], 'o-', label=f'{duration:g} s')
    left.axhline(1.0, color='k', linewidth=0.8, linestyle=':')
    right.axhline(0.1, color='k', linewidth=0.8, linestyle=':')
    left.set(title='time offset: worst error', xlabel='noise (deg rms)', ylabel='ms')
    right.set(title='world alignment and mounting: worst error', xlabel='noise (deg rms)',
              ylabel='deg')
    for axis in (left, right):
        axis.grid(True, which='both', alpha=0.3)
        axis.legend(title='record', fontsize='small')
    output = io.BytesIO()
    figure.savefig(output, format='png', dpi=100)
    return output.getvalue()
