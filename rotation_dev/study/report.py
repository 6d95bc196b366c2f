"""
The accuracy study as documents: ``accuracy.md`` (tables) and ``accuracy.png`` (plots).

Every number comes from the results of this run (:mod:`.measure`,
:mod:`.integration`); the verdicts under the tables (fastest method within
8 eps, cheapest integrator for a target error) are computed from them, and
only the reasons given for the package's choices are fixed text.
"""
import io
import os
import platform
import time

from matplotlib import ticker
from matplotlib.figure import Figure
import numpy as np

from . import methods, reference
from .measure import EXACT_EPS, FEATURED_SEQUENCES, NOISE_SIGMAS

#: Integration targets (rad) for the "cheapest method" verdicts.
INTEGRATION_TARGETS = (1e-3, 1e-6, 1e-9)
#: Errors are drawn at least this large on the log axes (an error of 0 has no log).
PLOT_FLOOR_EPS = 0.1

# Why the package's method is what it is, where a faster one exists (shown
# only when the measurements say a faster method stays within 8 eps).
_PACKAGE_REASONS = {
    'matrix': 'The package validates every matrix (finite, det > 0, orthonormality) and '
              "replaces a non-orthonormal one by its nearest rotation before Markley's "
              'formula; the bare formulas do neither, and land sigma away from the nearest '
              'rotation on noisy input (next table).',
    'noisy': 'Only the package and the SVD methods return the nearest rotation; the package '
             'reaches it by Newton-Schulz iteration, without an SVD.',
    'rotation_vector': 'The package validates its input and scales the quaternion by an exact '
                       'power of two, so that quaternions of any norm (1e-160 to 1e+160) '
                       'convert exactly; plain numpy norms overflow there.',
    'euler': 'The package validates its input and never snaps near gimbal lock.',
}


# ------------------------------------------------------------ formatting

def format_eps(value):
    """Format an error in eps for a table cell; large ones also in radians."""
    if not np.isfinite(value):
        return '—'
    if value < 100:
        return f'{value:.2f}'
    if value < 1e6:
        return f'{value:.0f}'
    return f'{value:.1e} ({value * reference.EPS:.1g} rad)'


def describe_eps(value):
    """Format an error in eps for a sentence: ``'1.24 eps'``, ``'1.4e+16 eps (3.1 rad)'``."""
    if not np.isfinite(value):
        return 'no finite output'
    if value < 1e6:
        return f'{format_eps(value)} eps'
    return f'{value:.1e} eps ({value * reference.EPS:.2g} rad)'


def format_eps32(value_eps64):
    """Format an error measured in eps (2**-52) in float32 eps (2**-23)."""
    if not np.isfinite(value_eps64):
        return '—'
    return f'{value_eps64 * reference.EPS / reference.EPS32:.2f}'


def format_ns(value):
    """Format a time per rotation in ns (None: not timed, or the method rejected the batch)."""
    if value is None:
        return '—'
    return f'{value:.1f}' if value < 1000 else f'{value:.0f}'


def markdown_table(header, rows):
    """Return a Markdown table; ``|`` inside a cell is escaped."""
    def line(cells):
        return '| ' + ' | '.join(str(c).replace('|', '\\|') for c in cells) + ' |'
    return '\n'.join([line(header), '|' + '|'.join('---' for _ in header) + '|']
                     + [line(row) for row in rows])


def environment():
    """Describe the machine, its load, and the Python and library versions in one line."""
    import mpmath
    import numba
    import scipy
    import transforms3d
    model = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as cpuinfo:
            model = next(line.split(':', 1)[1].strip() for line in cpuinfo
                         if line.startswith('model name'))
    except (OSError, StopIteration):
        pass
    load = ', '.join(f'{x:.2f}' for x in os.getloadavg()) if hasattr(os, 'getloadavg') else '?'
    return (f'{model}, {os.cpu_count()} CPUs (load average {load}); Python '
            f'{platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, '
            f'scipy {scipy.__version__}, transforms3d {transforms3d.__version__}, '
            f'mpmath {mpmath.__version__}')


# ------------------------------------------------------------ verdicts

def _verdict(family):
    """Say which method is fastest within 8 eps, which are faster but inexact, and why."""
    timed = family.timed_case

    def time_ns(row):
        return row.cases[timed].time_ns if timed in row.cases else None

    best = family.fastest_exact()
    package = next(r for r in family.rows if r.method.is_package)
    if best is None:
        lines = [f'No method stays within {EXACT_EPS:g} eps on every input set.']
    else:
        lines = [f'Fastest method within {EXACT_EPS:g} eps on every input set: '
                 f'**{best.method.name}** ({format_ns(time_ns(best))} ns per rotation, '
                 f'{timed}).']
        if best is not package:
            lines.append(f'{package.method.name}: {format_ns(time_ns(package))} ns. '
                         + _PACKAGE_REASONS[family.key])
    for row in family.rows:
        faster = (time_ns(row) is not None and time_ns(package) is not None
                  and time_ns(row) < time_ns(package))
        if faster and not family.exact(row):
            worst, failures = family.worst(row)
            lines.append(f'Faster but not within {EXACT_EPS:g} eps: {row.method.name} '
                         f'({format_ns(time_ns(row))} ns; worst {describe_eps(worst)}'
                         + (f', {failures} failures' if failures else '') + ').')
    return '\n'.join(lines)


# ------------------------------------------------------------ tables

def _conversion_table(family):
    """Matrix -> quaternion: one input set."""
    case = family.cases[0]
    rows = []
    for row in family.rows:
        result = row.cases[case]
        rows.append((_name(family, row), row.method.source, format_ns(result.time_ns),
                     format_eps(result.errors.worst), format_eps(result.errors.median),
                     str(result.errors.failures), _mark(family, row)))
    header = ('method', 'source', 'time (ns/rotation)', 'worst (eps)', 'median (eps)',
              'failures', f'≤ {EXACT_EPS:g} eps')
    return markdown_table(header, rows)


def _noisy_table(family):
    rows = []
    for row in family.rows:
        cells = []
        for case in family.cases:
            errors = row.cases[case].errors
            cells.append(format_eps(errors.worst)
                         + (f' ({errors.failures} failed)' if errors.failures else ''))
        rows.append((_name(family, row), *cells,
                     format_ns(row.cases[family.timed_case].time_ns), _mark(family, row)))
    header = ('method', *(f'σ = {s:.0e}' for s in NOISE_SIGMAS),
              f'time (ns), σ = {family.timed_case.split()[-1]}', f'≤ {EXACT_EPS:g} eps')
    return markdown_table(header, rows)


def _rotation_vector_table(family):
    unit, corpus = family.cases
    rows = []
    for row in family.rows:
        u, c = row.cases[unit], row.cases[corpus]
        rows.append((_name(family, row), row.method.source, format_ns(u.time_ns),
                     format_eps(u.errors.worst), format_eps(u.errors.median),
                     str(u.errors.failures), format_eps(c.errors.worst), str(c.errors.failures),
                     _mark(family, row)))
    header = ('method', 'source', 'time (ns/rotation)', 'unit: worst (eps)',
              'unit: median (eps)', 'unit: failures', 'corpus: worst (eps)', 'corpus: failures',
              f'≤ {EXACT_EPS:g} eps')
    return markdown_table(header, rows)


def _euler_table(family):
    shown = [s for s in FEATURED_SEQUENCES if s in family.cases]
    rows = []
    for row in family.rows:
        cells = [format_eps(row.cases[s].errors.worst) if s in row.cases else 'n/a'
                 for s in shown]
        worst, failures = family.worst(row)
        rows.append((_name(family, row), format_ns(row.cases[family.timed_case].time_ns),
                     *cells, format_eps(worst), str(failures), _mark(family, row)))
    header = ('method', f"time (ns/rotation), '{family.timed_case}'",
              *(f"'{s}' worst (eps)" for s in shown),
              f'all {len(family.cases)} measured: worst (eps)', 'failures',
              f'≤ {EXACT_EPS:g} eps')
    return markdown_table(header, rows)


def _name(family, row):
    best = family.fastest_exact()
    return f'**{row.method.name}**' if best is row else row.method.name


def _mark(family, row):
    return 'yes' if family.exact(row) else 'no'


def _float32_table(results):
    rows = [(f'`{r.function}`', r.inputs, format_eps(r.float64.worst),
             format_eps32(r.float32_output.worst), format_eps32(r.float32_end_to_end.worst),
             format_ns(r.time64_ns), format_ns(r.time32_ns)) for r in results]
    header = ('function', 'inputs', 'float64: worst (eps)',
              'float32, output rounding: worst (eps32)', 'float32, end to end: worst (eps32)',
              'time float64 (ns)', 'time float32 input (ns)')
    return markdown_table(header, rows)


def _integration_tables(scene):
    steps = [p.steps for p in scene.curves[0].points]
    rows = [(f'`{c.method}`', str(c.rates_per_step),
             *(f'{p.error:.1e} · {p.seconds * 1e3:.2f}' for p in c.points))
            for c in scene.curves]
    header = ('method', 'rates per step',
              *(f'N = {n} (h = {scene.duration / n:.2g} s)' for n in steps))
    return markdown_table(header, rows)


def _integration_verdicts(scene):
    lines = []
    for target in INTEGRATION_TARGETS:
        if target < 10 * scene.truth_resolution:
            lines.append(f'- {target:.0e} rad: below 10x the truth resolution '
                         f'({scene.truth_resolution:.1e} rad), not resolved.')
            continue
        reached = [(p.seconds, c.method, p) for c in scene.curves for p in c.points
                   if p.error <= target]
        if not reached:
            lines.append(f'- {target:.0e} rad: no method reached it at the steps measured.')
            continue
        seconds, method, point = min(reached, key=lambda x: x[0])
        lines.append(f'- {target:.0e} rad: cheapest `{method}`, N = {point.steps}, '
                     f'{seconds * 1e3:.2f} ms per call (error {point.error:.1e} rad).')
    return '\n'.join(lines)


# ------------------------------------------------------------ headline findings

def _rates(count):
    return f'{count} rate{"s" if count != 1 else ""} per step'


def _headlines(families, float32, scenes):
    """Write the findings, one bullet per family, every number from this run."""
    by_key = {f.key: f for f in families}

    def row(family, prefix):
        return next(r for r in family.rows if r.method.name.startswith(prefix))

    def worst(family, prefix):
        return family.worst(row(family, prefix))[0]

    lines = []
    matrix = by_key['matrix']
    textbook = row(matrix, 'textbook trace').cases[matrix.timed_case]
    lines.append(
        f'- Matrix to quaternion: {methods.PACKAGE} {describe_eps(worst(matrix, methods.PACKAGE))}'
        f' at {format_ns(row(matrix, methods.PACKAGE).cases[matrix.timed_case].time_ns)} ns '
        f'per rotation; the textbook trace formula returns NaN for '
        f'{textbook.errors.failures} of {textbook.errors.samples} hard matrices (rotations by '
        f'pi and near it) and is off by up to {describe_eps(textbook.errors.worst)} on the '
        f'others.')
    noisy = by_key['noisy']
    largest = noisy.cases[-1]
    pivots = max(row(noisy, name).cases[largest].errors.worst
                 for name in ('Shepperd', 'Markley', 'tf2'))
    lines.append(
        f'- Noisy matrices R + σN, σ from {NOISE_SIGMAS[0]:g} to {NOISE_SIGMAS[-1]:g}: '
        f'{methods.PACKAGE} stays within {describe_eps(worst(noisy, methods.PACKAGE))} of the '
        f'nearest rotation; Shepperd, Markley and tf2 land up to {describe_eps(pivots)} from it '
        f'at σ = {NOISE_SIGMAS[-1]:g} (they never look at the noise); SVD + Markley: '
        f'{describe_eps(worst(noisy, "SVD"))}.')
    rv = by_key['rotation_vector']
    unit, corpus = rv.cases
    textbook = row(rv, 'textbook 2 acos').cases[unit].errors
    atan2 = row(rv, '2 atan2').cases
    lines.append(
        f'- Quaternion to rotation vector: the textbook 2 acos(q_s) is off by up to '
        f'{describe_eps(textbook.worst)} and returns NaN for {textbook.failures} of '
        f'{textbook.samples} unit '
        f'quaternions (the smallest angles); 2 atan2(|q_v|, q_s) in plain numpy: '
        f'{describe_eps(atan2[unit].errors.worst)} on unit quaternions, '
        f'{describe_eps(atan2[corpus].errors.worst)} on the scaled corpus (np.linalg.norm '
        f'overflows at 1e+-160); {methods.PACKAGE}: {describe_eps(worst(rv, methods.PACKAGE))}'
        ' on both.')
    euler = by_key['euler']
    cells = [f'{name} {worst(euler, name) * reference.EPS:.1e} rad'
             for name in ('tf2', 'PlotJuggler', 'transforms3d', 'scipy')]
    lines.append(
        f'- Euler angles near gimbal lock ({len(euler.cases)} conventions), worst rotation '
        f'error: {", ".join(cells)}; {methods.PACKAGE} '
        f'{describe_eps(worst(euler, methods.PACKAGE))}.')
    worst32 = max(r.float32_end_to_end.worst for r in float32)
    lines.append(
        f"- float32 pipeline: the package's results stored as float32 are within "
        f'{format_eps32(worst32)} float32 eps of the exact rotation of the float64 input, '
        'input rounding included.')
    for scene in scenes:
        curves = {c.method: c for c in scene.curves}
        middle = len(curves['magnus4'].points) // 2
        cells = [f'{name} {curves[name].points[middle].error:.1e} rad '
                 f'({_rates(curves[name].rates_per_step)})'
                 for name in ('magnus4', 'rk4', 'coning2', 'midpoint_exp')]
        lines.append(f'- Integration, {scene.title}, N = {curves["magnus4"].points[middle].steps}'
                     f' steps: {", ".join(cells)}.')
    return '\n'.join(lines)


# ------------------------------------------------------------ the documents

def accuracy_markdown(families, float32, scenes, *, quick, settings, command, seconds):
    """
    Return the text of ``accuracy.md``.

    Parameters
    ----------
    families : list of FamilyResult
        The matrix, noisy matrix, rotation vector and Euler families.
    float32 : list of Float32Result
        The float32 comparison.
    scenes : list of SceneResult
        The integration study.
    quick : bool
        Whether this was a ``--quick`` run (smaller inputs).
    settings : Settings
        The sizes used.
    command : str
        The command that reproduces the document.
    seconds : float
        Run time of the measurements.

    Returns
    -------
    str
        Markdown.

    """
    by_key = {f.key: f for f in families}
    run = ' (**--quick**: fewer inputs, timings indicative)' if quick else ''
    parts = [
        '# Accuracy against time',
        '',
        f'Generated by `{command}` on {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}'
        f' in {seconds:.0f} s{run}.',
        f'Machine: {environment()}.',
        '',
        'Every method is measured in this run, on the same inputs, side by side; no number '
        'is quoted from elsewhere. The inputs are the hard cases described in '
        '[numerics.md](numerics.md) '
        '(`rotation_dev.hard_cases`).',
        '',
        '- **Error**: the geodesic angle between the rotation a method returns and the exact '
        'rotation of its input, `2 atan2(|vec(q_e* q_t)|, |scalar(q_e* q_t)|)`, in eps = '
        f'2^-52 = {reference.EPS:.3g} (1 rad = {1 / reference.EPS:.2g} eps). The exact '
        f'rotation is computed with mpmath at {reference.DIGITS} digits from the float input '
        'taken as the exact binary number it is. Euler angles are compared as the rotations '
        'they stand for, never angle by angle.',
        '- **Failures**: outputs with a NaN or Inf, and inputs the method rejects; worst and '
        'median are over the other samples.',
        f'- **Time**: per rotation, the inputs repeated into a batch of {settings.timing_batch} '
        f'rows, one thread, best of {settings.repeat} runs of at least 10 ms after a warm-up '
        'call; the errors are those of a call on that same batch. transforms3d has no batch '
        'form and is timed as the Python loop it needs.',
        f'- **≤ {EXACT_EPS:g} eps**: worst error within {EXACT_EPS:g} eps and no failure on '
        'every input set of the family. **Bold**: the fastest such method.',
        '',
        '## Findings',
        '',
        _headlines(families, float32, scenes),
        '',
        '![time per rotation against worst error, and integrators](accuracy.png)',
        '',
        '## 1. Matrix to quaternion',
        '',
        by_key['matrix'].inputs,
        '',
        _conversion_table(by_key['matrix']),
        '',
        _verdict(by_key['matrix']),
        '',
        '## 2. Matrix to quaternion, noisy matrices',
        '',
        by_key['noisy'].inputs + ' Cells: worst error (eps).',
        '',
        _noisy_table(by_key['noisy']),
        '',
        _verdict(by_key['noisy']),
        '',
        '## 3. Quaternion to rotation vector (angle and axis)',
        '',
        by_key['rotation_vector'].inputs + ' Timed on the unit quaternions.',
        '',
        _rotation_vector_table(by_key['rotation_vector']),
        '',
        _verdict(by_key['rotation_vector']),
        '',
        '## 4. Quaternion to Euler angles near gimbal lock',
        '',
        by_key['euler'].inputs + ' tf2 and PlotJuggler only do ROS roll, pitch, yaw '
        f"('{methods.ROS_RPY}'); 'n/a' where a method has no such convention. "
        f'Conventions measured: {", ".join(by_key["euler"].cases)}.',
        '',
        _euler_table(by_key['euler']),
        '',
        _verdict(by_key['euler']),
        '',
        '## 5. float32 pipeline against float64 (this package)',
        '',
        'The package computes in float64 whatever its input. A float32 pipeline gives it '
        'float32 arrays and stores its results as float32. Measured: inputs rounded to '
        'float32, the package called on the float32 array, its float64 result rounded to '
        'float32. Two errors of that result, in float32 eps (2^-23 = '
        f'{reference.EPS32:.3g}): against the exact rotation of the float32 input (what '
        'computing and storing the output adds) and against the exact rotation of the '
        'original float64 input (everything the float32 pipeline loses, input rounding '
        'included). The float64 column is the same function on the float64 inputs, in eps. '
        'Times are per rotation for float64 and for float32 input arrays (the conversion to '
        'float64 included).',
        '',
        _float32_table(float32),
        '',
        '## 6. Attitude integration: error against cost',
        '',
        "Every method of `integrate_angular_velocity`, the truth's body rate given as a "
        'function (evaluated where each method needs it), N equal steps over the scene. '
        'Cells: largest geodesic error over all output times (rad) · time per call (ms, '
        'best of repeats, rates precomputed so that only the integrator is timed). "Rates '
        'per step" counts the rate evaluations the method asked for.',
    ]
    for scene in scenes:
        parts += [
            '',
            f'### {scene.title} (`{scene.scene_file}`, {scene.duration:g} s)',
            '',
            f'Truth resolution: {scene.truth_resolution:.1e} rad (the truth at the finest '
            'output times against the truth on a grid 4x finer).'
            + (' The motion is ill-conditioned (a spin near the intermediate axis): '
               'differences of round-off size grow by orders of magnitude over the flips, so '
               'errors below this level are not resolved.'
               if scene.truth_resolution > 1e-13 else ''),
            '',
            _integration_tables(scene),
            '',
            'Cheapest method measured for a target error:',
            '',
            _integration_verdicts(scene),
        ]
    return '\n'.join(parts) + '\n'


# ------------------------------------------------------------ plots

_MARKERS = 'osD^v<>ph'


def _styles(families):
    """Give each method a colour and marker, the same in every panel; the package's black stars."""
    styles = {}
    peers = dict.fromkeys(r.method.name for f in families for r in f.rows
                          if not r.method.is_package)
    for index, name in enumerate(peers):
        styles[name] = {'color': f'C{index % 10}', 'marker': _MARKERS[index % len(_MARKERS)],
                        'markersize': 7, 'zorder': 3}
    for family in families:
        for row in family.rows:
            if row.method.is_package:
                styles[row.method.name] = {'color': 'black', 'marker': '*', 'markersize': 13,
                                           'zorder': 5}
    return styles


def _plain_log_ticks(axis):
    """Label a log x axis with plain numbers (10, 100) rather than powers of ten."""
    formatter = ticker.FuncFormatter(lambda value, _: f'{value:g}')
    axis.xaxis.set_major_formatter(formatter)
    axis.xaxis.set_minor_formatter(ticker.NullFormatter())


def _plot_family(axis, family, title, styles):
    for row in family.rows:
        time_ns = row.cases[family.timed_case].time_ns
        if time_ns is None:
            continue
        worst, failures = family.worst(row)
        label = row.method.name + (f' ({failures} failures)' if failures else '')
        axis.plot(time_ns, max(worst, PLOT_FLOOR_EPS), linestyle='none', label=label,
                  **styles[row.method.name])
    _eps_axes(axis, title)
    axis.set_xscale('log')
    _plain_log_ticks(axis)
    where = f", '{family.timed_case}'" if family.key == 'euler' else ''
    axis.set_xlabel(f'time per rotation (ns){where}')


def _eps_axes(axis, title):
    axis.set_yscale('log')
    axis.axhline(EXACT_EPS, color='grey', linestyle=':', linewidth=1)
    axis.text(1.0, EXACT_EPS, f' {EXACT_EPS:g} eps', transform=axis.get_yaxis_transform(),
              va='bottom', ha='right', fontsize=7, color='grey')
    axis.set_ylabel('worst error (eps)')
    axis.set_title(title, fontsize=10)
    axis.grid(True, which='major', alpha=0.3)


def _plot_noisy(axis, family, styles):
    for row in family.rows:
        worst = [row.cases[c].errors.worst for c in family.cases]
        axis.plot(NOISE_SIGMAS, np.maximum(worst, PLOT_FLOOR_EPS), label=row.method.name,
                  **{**styles[row.method.name], 'markersize': 5})
    axis.plot(NOISE_SIGMAS, np.array(NOISE_SIGMAS) / reference.EPS, color='grey',
              linestyle='--', linewidth=1, label='σ')
    _eps_axes(axis, 'Matrix to quaternion, R + σN: distance from nearest rotation')
    axis.set_xscale('log')
    axis.set_xlabel('noise σ')


def _plot_integration(axis, scene):
    for index, curve in enumerate(scene.curves):
        axis.plot([p.seconds * 1e3 for p in curve.points], [p.error for p in curve.points],
                  marker=_MARKERS[index], markersize=4, label=curve.method, color=f'C{index}')
    if scene.truth_resolution > 0:
        axis.axhline(scene.truth_resolution, color='grey', linestyle=':', linewidth=1)
        axis.text(0.0, scene.truth_resolution, ' truth resolution', fontsize=7, color='grey',
                  transform=axis.get_yaxis_transform(), va='bottom')
    axis.set_xscale('log')
    axis.set_yscale('log')
    _plain_log_ticks(axis)
    axis.set_xlabel('time per call (ms)')
    axis.set_ylabel('largest error (rad)')
    axis.set_title(f'Integration: {scene.title}\n({scene.duration:g} s, N from '
                   f'{scene.curves[0].points[0].steps} to {scene.curves[0].points[-1].steps})',
                   fontsize=10)
    axis.grid(True, which='major', alpha=0.3)


def accuracy_png(families, scenes):
    """
    Return the bytes of ``accuracy.png``.

    One panel per conversion family (time per rotation against worst error,
    log-log, one point per method; noisy matrices: worst error against σ) and
    one per integration scene (error against time per call, one curve per
    method over the step sizes).

    """
    by_key = {f.key: f for f in families}
    styles = _styles(families)
    figure = Figure(figsize=(19, 11.5))    # no pyplot: no global state, Agg for PNG
    axes = figure.subplots(2, 3)
    _plot_family(axes[0, 0], by_key['matrix'], 'Matrix to quaternion (hard matrices)', styles)
    _plot_noisy(axes[0, 1], by_key['noisy'], styles)
    _plot_family(axes[0, 2], by_key['rotation_vector'],
                 'Quaternion to rotation vector (unit and scaled quaternions)', styles)
    _plot_family(axes[1, 0], by_key['euler'], 'Quaternion to Euler near gimbal lock '
                 f'({len(by_key["euler"].cases)} conventions)', styles)
    for axis, scene in zip(axes[1, 1:], scenes):
        _plot_integration(axis, scene)
    for axis in axes.flat:
        axis.legend(fontsize=7, loc='best')
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format='png', dpi=90)
    return buffer.getvalue()
