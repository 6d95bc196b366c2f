"""
``python -m rotation_dev.study [--quick] [--out DIR]``: the accuracy study and performance summary.

Writes ``DIR/accuracy.md``, ``DIR/accuracy.png``, ``DIR/covariance.png`` (the
Euler-covariance section's plot), ``DIR/compare_accuracy.png`` (the two-stream
section's) and ``DIR/performance.md`` (default ``DIR``: ``docs``), each through
a temporary file renamed into place.
``--quick`` (for CI) uses fewer inputs and runs only the library benchmark; it
finishes in about a minute; the full run takes about seven (two of them the
two-stream section). Progress goes to stderr.

Run from the repository root with the development environment (``.venv``).

Errors are one line on stderr, ``python -m rotation_dev.study: error: ...``, and exit status
1: a bad ``--out`` (not a directory, not writable) or a missing
``benchmarks/`` before anything is measured; a benchmark that failed after the
documents are written (performance.md says which and why). Ctrl-C exits with
status 130; the documents are written only at the end, so an interrupted run
leaves the previous ones in place, and none is ever half-written.
"""
import argparse
import os
import sys
import tempfile
import time

from rotation_node.bag.writing.atomic_file import AtomicFile
from rotation_node.errors import BagError

#: How the study is run, as its messages and documents name it.
PROG = 'python -m rotation_dev.study'


def build_parser():
    """Return the command-line parser of the study."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Measure every conversion method and peer on the hard cases (time per '
                    'rotation against worst error in eps), the attitude integrators against '
                    "exact truth, and the benchmarks' ratios; write accuracy.md, accuracy.png "
                    'and performance.md.')
    parser.add_argument('--quick', action='store_true',
                        help='fewer inputs and the library benchmark only (under a minute)')
    parser.add_argument('--out', default='docs', metavar='DIR',
                        help='directory to write the documents to (default: docs)')
    return parser


def _check_output_directory(path):
    """Create ``path`` if needed and make sure a file can be created in it; OSError otherwise."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise NotADirectoryError(f'--out {path} is not a directory')
    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:
        raise OSError(f'cannot write to --out {path}: {error.strerror}') from None


def _write(path, data):
    """Write ``data`` (str or bytes) to ``path``: a temporary file renamed into place."""
    with AtomicFile(path, overwrite=True) as output:
        output.stream.write(data.encode() if isinstance(data, str) else data)


class _Progress:
    """Stage lines on stderr, with the time since the start."""

    def __init__(self):
        self.start = time.monotonic()

    def __call__(self, message):
        print(f'[{time.monotonic() - self.start:6.1f} s] {message}', file=sys.stderr, flush=True)


def _measure_and_write(args):
    """Run the study and the benchmarks, write the documents; return the exit status."""
    from . import comparison, covariance, integration, measure, performance, report
    command = PROG + (' --quick' if args.quick else '')
    settings = measure.QUICK if args.quick else measure.FULL
    progress = _Progress()

    families = []
    for study in (measure.matrix_to_quaternion, measure.noisy_matrix_to_quaternion,
                  measure.quaternion_to_rotation_vector, measure.quaternion_to_euler):
        families.append(study(settings))
        progress(families[-1].title)
    float32 = measure.float32_pipeline(settings)
    progress('float32 pipeline')
    scenes = integration.integration_study(settings)
    progress('integration')
    covariance_rows = covariance.measure(quick=args.quick)
    progress('Euler covariance against Monte Carlo')
    comparison_rows = comparison.measure(quick=args.quick)
    progress('two streams: time offset, world alignment and mounting')
    study_seconds = time.monotonic() - progress.start
    environment = report.environment()

    runs = []
    for benchmark in performance.BENCHMARKS:
        runs.append(performance.run_benchmark(benchmark, args.quick))
        progress(f'{benchmark.script}: {runs[-1].status} {runs[-1].detail}'.rstrip())

    outputs = {
        'accuracy.md': report.accuracy_markdown(
            families, float32, scenes, quick=args.quick, settings=settings, command=command,
            seconds=study_seconds).rstrip('\n') + '\n\n'
        + covariance.covariance_markdown(covariance_rows, heading='## 7.')
        + '\n' + comparison.comparison_markdown(comparison_rows, heading='## 8.'),
        'accuracy.png': report.accuracy_png(families, scenes),
        'covariance.png': covariance.covariance_png(covariance_rows),
        'compare_accuracy.png': comparison.comparison_png(comparison_rows),
        'performance.md': performance.performance_markdown(
            runs, quick=args.quick, command=command, environment=environment),
    }
    for name, data in outputs.items():
        _write(os.path.join(args.out, name), data)
    progress(f'wrote {", ".join(os.path.join(args.out, n) for n in outputs)}')
    failed = [run.benchmark.script for run in runs if run.status == 'failed']
    if failed:
        print(f'{PROG}: error: {", ".join(failed)} failed (see performance.md)',
              file=sys.stderr)
    return 1 if failed else 0


def main(argv=None):
    """Run the study; return the exit status."""
    args = build_parser().parse_args(argv)
    try:
        _check_output_directory(args.out)
        # The study's modules (matplotlib, scipy) only once the arguments are usable: a
        # mistyped --out is answered at once.
        from . import performance
        performance.require_benchmarks()
        return _measure_and_write(args)
    except (OSError, BagError) as error:
        print(f'{PROG}: error: {error}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
