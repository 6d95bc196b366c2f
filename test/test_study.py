"""
Tests of rotation_dev.study: ``python -m rotation_dev.study --quick`` writes complete documents.

The run's tables must hold a row for every family and method of the study with
finite numbers; the stability claims themselves (errors within a few eps) are
asserted in the library's own tests, not here.
"""
import math
import os
import re
import subprocess
import sys
import time

import pytest
from rotation_dev.paths import REPOSITORY
from rotation_dev.study import comparison, covariance, integration, measure, methods
from rotation_node.kinematics import INTEGRATION_METHODS

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

STUDY = (sys.executable, '-m', 'rotation_dev.study')
#: Bound on one quick run (it takes about a minute on an idle machine).
QUICK_TIMEOUT_S = 300.0
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


@pytest.fixture(scope='module')
def quick_run(tmp_path_factory):
    """One quick run of the study: (output directory, completed process, seconds)."""
    out = tmp_path_factory.mktemp('docs')
    start = time.monotonic()
    process = subprocess.run([*STUDY, '--quick', '--out', str(out)], cwd=REPOSITORY,
                             capture_output=True, text=True, timeout=QUICK_TIMEOUT_S)
    return out, process, time.monotonic() - start


@pytest.fixture(scope='module')
def accuracy(quick_run):
    return _sections((quick_run[0] / 'accuracy.md').read_text())


@pytest.fixture(scope='module')
def performance(quick_run):
    return _sections((quick_run[0] / 'performance.md').read_text())


def _sections(markdown):
    """``{heading: {first cell: row cells}}`` for every table under a ``##``/``###`` heading."""
    sections, heading = {}, None
    for line in markdown.splitlines():
        if line.startswith('#'):
            heading = line.lstrip('#').strip()
            sections[heading] = {}
        elif line.startswith('|') and not line.startswith('|---') and heading is not None:
            cells = [c.strip().replace('\\|', '|')
                     for c in re.split(r'(?<!\\)\|', line.strip().strip('|'))]
            # The first table under a heading wins (performance.md has two per benchmark).
            sections[heading].setdefault(cells[0].strip('*`'), cells[1:])
    return sections


def _section(sections, prefix):
    matches = [rows for heading, rows in sections.items() if heading.startswith(prefix)]
    assert len(matches) == 1, f'no single section starting with {prefix!r}: {list(sections)}'
    return matches[0]


def _number(cell):
    """Return the first number of a cell (``'1.4e+16 (3 rad)'`` -> 1.4e16), or NaN."""
    match = re.search(r'[-+]?\d+(\.\d+)?(e[-+]?\d+)?', cell)
    return float(match.group(0)) if match else math.nan


def _assert_finite(row, columns, what):
    for column in columns:
        assert math.isfinite(_number(row[column])), f'{what}: column {column} is {row[column]!r}'


def test_quick_run_succeeds_and_writes_the_three_documents(quick_run):
    out, process, _ = quick_run
    assert process.returncode == 0, process.stderr
    assert sorted(os.listdir(out)) == ['accuracy.md', 'accuracy.png', 'compare_accuracy.png',
                                       'covariance.png', 'performance.md']


def test_accuracy_png_is_a_png(quick_run):
    data = (quick_run[0] / 'accuracy.png').read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    assert len(data) > 10_000


def test_accuracy_has_the_euler_covariance_section_and_its_plot(quick_run, accuracy):
    assert (quick_run[0] / 'covariance.png').read_bytes().startswith(PNG_SIGNATURE)
    section = accuracy['7. Euler-angle covariance: first order against Monte Carlo']
    assert {f'{math.degrees(sigma):.3g}' for sigma in covariance.SIGMA_SWEEP} <= set(section)
    assert all(row[-1].endswith('%') for key, row in section.items() if key != 'sigma (deg)')
    assert '](covariance.png)' in (quick_run[0] / 'accuracy.md').read_text()


def test_accuracy_has_the_two_stream_section_and_its_plot(quick_run, accuracy):
    assert (quick_run[0] / 'compare_accuracy.png').read_bytes().startswith(PNG_SIGNATURE)
    section = accuracy['8. Two streams: time offset, world alignment and mounting']
    assert {f'{noise:g}' for noise in comparison.QUICK_NOISE_DEG} <= set(section)
    for key, row in section.items():
        if key != 'noise (deg)':
            _assert_finite(row, range(8), key)
    assert '](compare_accuracy.png)' in (quick_run[0] / 'accuracy.md').read_text()


@pytest.mark.parametrize('section, family', [
    ('1. Matrix to quaternion', methods.MATRIX_TO_QUATERNION),
    ('3. Quaternion to rotation vector', methods.QUATERNION_TO_ROTATION_VECTOR),
])
def test_conversion_tables_have_every_method_with_time_and_worst_error(accuracy, section, family):
    rows = _section(accuracy, section)
    for method in family:
        # method | source | time | worst | median | failures ...
        _assert_finite(rows[method.name], (1, 2, 3, 4), method.name)


def test_noisy_matrix_table_has_every_method_and_noise_level(accuracy):
    rows = _section(accuracy, '2. Matrix to quaternion, noisy')
    for method in methods.MATRIX_TO_QUATERNION:
        # one worst error per sigma, then the time
        _assert_finite(rows[method.name], range(len(measure.NOISE_SIGMAS) + 1), method.name)


def test_euler_table_has_every_method_and_convention(accuracy):
    rows = _section(accuracy, '4. Quaternion to Euler')
    for method in methods.QUATERNION_TO_EULER:
        cells = rows[method.name]
        # time, one column per featured convention, the worst over all of them
        for column, seq in enumerate(measure.FEATURED_SEQUENCES, start=1):
            if method.sequences is None or seq in method.sequences:
                _assert_finite(cells, (column,), f'{method.name} {seq}')
            else:
                assert cells[column] == 'n/a'
        _assert_finite(cells, (0, len(measure.FEATURED_SEQUENCES) + 1), method.name)


def test_float32_table_has_every_package_function(accuracy):
    rows = _section(accuracy, '5. float32')
    rpy = methods.ROS_RPY
    for name in ('quaternion_from_matrix', 'rotation_vector_from_quaternion',
                 'quaternion_from_rotation_vector', f"euler_from_quaternion(q, '{rpy}')",
                 f"quaternion_from_euler(a, '{rpy}')"):
        # inputs | float64 worst | float32 output rounding | end to end | time 64 | time 32
        _assert_finite(rows[name], range(1, 6), name)


@pytest.mark.parametrize('scene', integration.SCENES)
def test_integration_tables_have_every_method_and_step(accuracy, scene):
    title = integration.SCENES[scene][1]
    rows = _section(accuracy, title)
    steps = measure.QUICK.integration_steps[scene]
    for method in INTEGRATION_METHODS:
        cells = rows[method]
        assert len(cells) == 1 + len(steps)
        for cell in cells[1:]:
            error, milliseconds = (float(x) for x in cell.split('·'))
            assert math.isfinite(error) and math.isfinite(milliseconds) and milliseconds > 0


def test_findings_name_every_family(quick_run):
    findings = (quick_run[0] / 'accuracy.md').read_text().split('## Findings')[1].split('##')[0]
    for words in ('Matrix to quaternion', 'Noisy matrices', 'rotation vector', 'Euler',
                  'float32', 'Integration'):
        assert words in findings


def test_performance_has_the_library_ratios(performance):
    rows = _section(performance, 'Library against scipy')
    # the conversions' table (the section also has the peers' table, by operation)
    conversions = {name: cells for name, cells in rows.items()
                   if re.fullmatch(r'[a-z_]+_from_[a-z_]+', name)}
    assert {'quaternion_from_matrix', 'euler_from_quaternion',
            'rotation_vector_from_quaternion'} <= set(conversions)
    for name, cells in conversions.items():
        # single: package, scipy, reference, ratio; met; batch: package, scipy, speed-up
        _assert_finite(cells, (0, 1, 2, 3, 5, 6, 7), name)


def test_performance_lists_the_node_and_bag_benchmarks_with_their_commands(quick_run):
    text = (quick_run[0] / 'performance.md').read_text()
    assert 'benchmarks/bench_node.py' in text
    assert 'benchmarks/bench_bag_convert.py' in text


@pytest.mark.parametrize('make_out', [
    lambda tmp: tmp / 'a_file',              # --out is a file
    lambda tmp: tmp / 'a_file' / 'docs',     # --out is under a file
])
def test_unusable_out_is_a_one_line_error(tmp_path, make_out):
    (tmp_path / 'a_file').write_text('not a directory')
    process = subprocess.run([*STUDY, '--quick', '--out', str(make_out(tmp_path))],
                             cwd=REPOSITORY, capture_output=True, text=True, timeout=60)
    assert process.returncode == 1
    assert process.stderr.startswith('python -m rotation_dev.study: error: ')
    assert len(process.stderr.strip().splitlines()) == 1
    assert (tmp_path / 'a_file').read_text() == 'not a directory'
