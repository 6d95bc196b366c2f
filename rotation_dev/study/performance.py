"""
The performance summary, ``performance.md``: the repository's benchmarks, run now.

Three benchmark scripts of ``benchmarks/`` measure the package against a peer
side by side in one run; this module runs them as they are (each in its own
process) and collects their ratios, with the command that reproduces each:

- ``bench_conversions.py``: the library against scipy, single sample and
  batch (the batch speed-up in several interleaved rounds), time per
  rotation from 10^2 to 10^6 samples, and the product, the rotation and
  single Euler samples against numpy-quaternion and the plain-Python formula
  (its ``--json`` results are read);
- ``bench_node.py``: CPU time per message of the live node against a bare
  rclpy relay (its printed median ratio is read);
- ``bench_bag_convert.py``: ``rotation_bag convert`` against the naive
  mcap-ros2-support + scipy pipeline and against the floor of reading and
  writing the same bag with ``mcap`` alone (its two printed ratios are read).

A ``--quick`` run measures the library only (``bench_conversions.py --quick --rounds 1``:
one pass of the single samples, one round of the batch and peer comparisons, indicative
timings in a fifth of the time);
the node and converter benchmarks are listed with their commands.
"""
import dataclasses
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from typing import Optional, Tuple

from rotation_dev.paths import BENCHMARKS_DIR, REPOSITORY

from .report import markdown_table

#: How the documents spell the interpreter in a command.
PYTHON = '.venv/bin/python'
#: bench_conversions' target for the single-sample ratio: package / scipy's
#: ``Rotation.from_quat(q).as_euler(seq)``, the single-sample reference (its batch targets
#: are in its results).
SINGLE_SAMPLE_TARGET = 0.10


@dataclasses.dataclass(frozen=True)
class Ratio:
    """
    One ratio a benchmark script prints, and its target (the script's own).

    Attributes
    ----------
    name : str
        What it divides, e.g. ``'naive / ours'``.
    target : str
        ``'<= x'`` or ``'>= x'``.
    pattern : str
        Regular expression whose group 1 is the ratio in the printed output.

    """

    name: str
    target: str
    pattern: str

    def meets(self, ratio):
        """Return whether ``ratio`` meets the target."""
        relation, bound = self.target.split()
        return ratio <= float(bound) if relation == '<=' else ratio >= float(bound)


@dataclasses.dataclass(frozen=True)
class Benchmark:
    """
    One benchmark script and how to read its ratios.

    Attributes
    ----------
    key, title : str
    script : str
        File name under ``benchmarks/``.
    quick_args, full_args : tuple of str or None
        Arguments in a quick and in a full run; None: not run.
    ratio : str
        What the ratios are (package against peer).
    ratios : tuple of Ratio
        The ratios read from the printed output, with their targets; empty:
        the results are read from the script's JSON output instead.
    timeout : float
        Seconds before the run is abandoned.
    json_target : str
        The targets, in words, of a benchmark read from its JSON output.

    """

    key: str
    title: str
    script: str
    quick_args: Optional[Tuple[str, ...]]
    full_args: Optional[Tuple[str, ...]]
    ratio: str
    ratios: Tuple[Ratio, ...]
    timeout: float
    json_target: str = ''

    def args(self, quick):
        """Return the script's arguments in this run, or None if it is not run."""
        return self.quick_args if quick else self.full_args

    def command(self, args):
        """Return the shell command that reproduces the run."""
        return ' '.join((PYTHON, f'benchmarks/{self.script}', *args))

    @property
    def target(self):
        """Return the targets in words, as the summary table shows them."""
        if not self.ratios:
            return self.json_target
        if len(self.ratios) == 1:
            return self.ratios[0].target
        return ', '.join(f'{r.name} {r.target}' for r in self.ratios)


LIBRARY = Benchmark(
    'library', 'Library against scipy', 'bench_conversions.py', ('--quick', '--rounds', '1'), (),
    'time, package / scipy from_quat().as_euler() (single sample) and scipy / package '
    '(batch), per conversion', (), 600.0,
    json_target=f'single sample <= {SINGLE_SAMPLE_TARGET:.2f}, batch speed-up >= 2 '
                '(>= 3 Euler)')
NODE = Benchmark(
    'node', 'Node against a bare relay', 'bench_node.py', None, (),
    'CPU time per message, rotation_node / bare relay (median)',
    (Ratio('rotation_node / relay', '<= 1.0',
           r'median ratio rotation_node / relay = ([0-9.]+)'),), 300.0)
BAG = Benchmark(
    'bag', 'Bag converter against the naive pipeline and the mcap floor', 'bench_bag_convert.py',
    None, (),
    'CPU time, naive (mcap-ros2-support + scipy per message) / rotation_bag convert, and '
    'rotation_bag convert / floor (reading and writing the same bag with mcap alone)',
    (Ratio('naive / ours', '>= 10', r'ratio naive/ours: ([0-9.]+)x'),
     Ratio('ours / floor', '<= 2', r'ours/floor: ([0-9.]+)x')), 1800.0)
BENCHMARKS = (LIBRARY, NODE, BAG)


@dataclasses.dataclass(frozen=True)
class BenchmarkRun:
    """
    The outcome of one benchmark in this run.

    Attributes
    ----------
    benchmark : Benchmark
    command : str
        Reproduces it (the JSON file name is a placeholder).
    status : {'measured', 'not run', 'failed'}
    seconds : float
        Wall time of the run.
    output : str
        What it printed.
    ratios : tuple of float or None
        The ratios read from the output (node, bag), as ``benchmark.ratios``.
    results : dict or None
        The JSON results (library).
    detail : str
        Why it failed or was not run.

    """

    benchmark: Benchmark
    command: str
    status: str
    seconds: float = 0.0
    output: str = ''
    ratios: Optional[Tuple[float, ...]] = None
    results: Optional[dict] = None
    detail: str = ''


def require_benchmarks():
    """Raise ``FileNotFoundError`` (one line) unless the benchmark scripts are there."""
    missing = [b.script for b in BENCHMARKS
               if not os.path.isfile(os.path.join(BENCHMARKS_DIR, b.script))]
    if missing:
        raise FileNotFoundError(
            f'{", ".join(missing)} not found in {BENCHMARKS_DIR} (performance.md needs the '
            'benchmarks of a source checkout)')


def run_benchmark(benchmark, quick):
    """
    Run one benchmark script as its own process and read its ratios.

    Parameters
    ----------
    benchmark : Benchmark
        The script and how to read it.
    quick : bool
        Whether this is a ``--quick`` run.

    Returns
    -------
    BenchmarkRun
        Its status, output and ratios (or JSON results).

    """
    args = benchmark.args(quick)
    if args is None:
        args = benchmark.full_args
        return BenchmarkRun(benchmark, benchmark.command(args), 'not run',
                            detail='--quick runs the library benchmark only')
    with tempfile.TemporaryDirectory() as directory:
        json_path = os.path.join(directory, 'results.json')
        extra = () if benchmark.ratios else ('--json', json_path)
        command = benchmark.command(args + (('--json', 'results.json') if extra else ()))
        start = time.monotonic()
        try:
            process = subprocess.run(
                [sys.executable, os.path.join(BENCHMARKS_DIR, benchmark.script), *args, *extra],
                capture_output=True, text=True, timeout=benchmark.timeout,
                cwd=REPOSITORY)
        except subprocess.TimeoutExpired:
            return BenchmarkRun(benchmark, command, 'failed', benchmark.timeout,
                                detail=f'timed out after {benchmark.timeout:.0f} s')
        seconds = time.monotonic() - start
        if process.returncode != 0:
            # A script may fail its own checks after measuring (bench_node: messages
            # lost): keep what it printed and say how it ended.
            last = process.stderr.strip().splitlines()[-1:] or ['its output is below']
            return BenchmarkRun(benchmark, command, 'failed', seconds, process.stdout,
                                detail=f'exit status {process.returncode}; {last[0]}')
        if not benchmark.ratios:
            with open(json_path) as stream:
                return BenchmarkRun(benchmark, command, 'measured', seconds, process.stdout,
                                    results=json.load(stream))
    ratios = read_ratios(benchmark, process.stdout)
    if ratios is None:
        return BenchmarkRun(benchmark, command, 'failed', seconds, process.stdout,
                            detail='its output lacks a ratio line (format changed?)')
    return BenchmarkRun(benchmark, command, 'measured', seconds, process.stdout, ratios=ratios)


def read_ratios(benchmark, output):
    """Return the values of ``benchmark.ratios`` printed in ``output`` (None: one is missing)."""
    matches = [re.search(ratio.pattern, output) for ratio in benchmark.ratios]
    if any(match is None for match in matches):
        return None
    return tuple(float(match.group(1)) for match in matches)


# ------------------------------------------------------------ the document

def _met(ok):
    return 'yes' if ok else '**no**'


def _library_tables(results):
    results, results_peers = results['conversions'], results['peers']
    sizes = list(next(iter(results.values()))['growth_ns'])
    batch_n = next(iter(results.values()))['batch_n']
    summary = markdown_table(
        ('conversion', 'single: package (µs)', 'single: scipy, same conversion (µs)',
         'single: reference (µs)', 'single: ratio package/reference',
         f'single ≤ {SINGLE_SAMPLE_TARGET:.2f}',
         f'batch 10^{len(str(batch_n)) - 1}: package (ns)', 'batch: scipy (ns)',
         'batch: speed-up scipy/package (best times)', 'speed-up in each round',
         'speed-up target', 'batch target met'),
        [(f'`{name}`', f'{r["single_us"]:.2f}', f'{r["single_scipy_us"]:.2f}',
          f'{r["single_reference_us"]:.2f}', f'{r["single_ratio"]:.3f}',
          _met(r['single_ratio'] <= SINGLE_SAMPLE_TARGET),
          f'{r["batch_ns"]:.1f}', f'{r["batch_scipy_ns"]:.1f}', f'{r["batch_speedup"]:.1f}x',
          _span(r['batch_speedup_rounds'], 'x'), f'{r["batch_target"]:g}x',
          _met(min(r['batch_speedup_rounds']) >= r['batch_target']))
         for name, r in results.items()])
    growth = markdown_table(
        ('conversion', *(f'10^{len(n) - 1}' for n in sizes)),
        [(f'`{name}`', *(f'{ours:.1f} / {scipy:.1f}' for ours, scipy in r['growth_ns'].values()))
         for name, r in results.items()])
    return summary, growth, _peer_table(results_peers)


def _span(values, unit=''):
    """Return ``'a to b'``, the smallest and the largest of ``values``."""
    return f'{min(values):.2f}{unit} to {max(values):.2f}{unit}'


def _per_sample(ns):
    return f'{ns:.1f} ns' if ns < 1000 else f'{ns / 1000:.2f} µs'


def _peer_table(peers):
    """Return the table of the product, the rotation and single Euler samples against peers."""
    rows = []
    for group, calls in peers.items():
        ours = next(iter(calls.values()))['round_ns']
        for k, (call, t) in enumerate(calls.items()):
            rows.append((group if k == 0 else '', call, _per_sample(t['best_ns']),
                         '' if k == 0 else _span([a / b for a, b in zip(ours, t['round_ns'])])))
    return markdown_table(('operation', 'call', 'time per sample (best round)',
                           'ratio first call / this call, each round'), rows)


def _library_headline(results):
    results = results['conversions']
    worst = max(results.items(), key=lambda item: item[1]['single_ratio'])
    rounds = {name: r['batch_speedup_rounds'] for name, r in results.items()}
    slowest = min(rounds.items(), key=lambda item: min(item[1]))
    best = max(rounds.items(), key=lambda item: max(item[1]))
    return (f'single sample: worst ratio {worst[1]["single_ratio"]:.3f} (`{worst[0]}`); '
            f'batch: speed-up {min(slowest[1]):.1f}x (`{slowest[0]}`) to '
            f'{max(best[1]):.1f}x (`{best[0]}`), lowest and highest round')


def _summary_cell(run):
    if run.status == 'not run':
        return f'not measured ({run.detail}): run the command'
    if run.status == 'failed':
        return f'failed ({run.detail})'
    if run.results is not None:
        return _library_headline(run.results)
    return '; '.join(_measured_ratios(run, with_target=False))


def _measured_ratios(run, *, with_target):
    """Return a phrase per ratio of ``run``: its value, its name and whether it met its target."""
    phrases = []
    for ratio, value in zip(run.benchmark.ratios, run.ratios):
        met = 'target met' if ratio.meets(value) else 'target **missed**'
        name = f' {ratio.name}' if len(run.benchmark.ratios) > 1 else ''
        phrases.append(f'**{value:.3f}**{name} ('
                       + (f'target {ratio.target}: {met})' if with_target else f'{met})'))
    return phrases


def performance_markdown(runs, *, quick, command, environment):
    """
    Return the text of ``performance.md``.

    Parameters
    ----------
    runs : list of BenchmarkRun
        In the order of :data:`BENCHMARKS`.
    quick : bool
        Whether this is a ``--quick`` run.
    command : str
        The command that wrote the document.
    environment : str
        Machine and versions.

    Returns
    -------
    str
        Markdown.

    """
    parts = [
        '# Performance summary',
        '',
        f'Generated by `{command}` on {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}'
        + (' (**--quick**: library benchmark only, in its quick form)' if quick else '') + '.',
        f'Machine: {environment}.',
        '',
        'Every ratio below was measured in this run by the benchmark script named, which '
        'times the package and its peer side by side in one process run; the command '
        'reproduces it. Accuracy against time, method by method, is in '
        '[accuracy.md](accuracy.md).',
        '',
        markdown_table(('benchmark', 'ratio', 'measured in this run', 'target', 'command'),
                       [(run.benchmark.title, run.benchmark.ratio, _summary_cell(run),
                         run.benchmark.target, f'`{run.command}`') for run in runs]),
    ]
    for run in runs:
        parts += ['', f'## {run.benchmark.title}', '', f'Command: `{run.command}`'
                  + (f' ({run.seconds:.0f} s in this run)' if run.status == 'measured' else ''),
                  '']
        if run.status != 'measured':
            parts.append(f'Not measured in this run: {run.detail}.' if run.status == 'not run'
                         else f'The benchmark failed in this run ({run.detail}).')
            if run.output:
                parts += ['', '```', run.output.rstrip(), '```']
            continue
        if run.results is not None:
            summary, growth, peers = _library_tables(run.results)
            machine = run.output.strip().split('\n\n')[0].splitlines()[:4]
            parts += ['Where it ran (the first lines of its output):', '', '```', *machine,
                      '```', '']
            parts += [
                'Single sample: time per call, validation included (shape (4,), (3,) or (3, 3)); '
                "the best turn of 200 calls, in turns interleaved with scipy's same conversion "
                'and the reference, over several passes through all rows.'
                ' Batch: time per rotation, the best over several rounds, the package and scipy '
                'interleaved in each; the speed-up of each round is given as a range. Ratio = '
                'package / scipy (lower is better); speed-up = scipy / package (higher is '
                'better).', '', summary, '',
                'Time per rotation (ns) as the batch grows, package / scipy:', '', growth, '',
                'Against other peers, in rounds (every call of an operation '
                'interleaved in each round; large batches of the package on its threads, '
                'and on one): numpy-quaternion on its own quaternion arrays '
                '(no conversion counted) and from `(x, y, z, w)` float arrays (the conversion '
                'to its scalar-first layout and, for the product, back counted); '
                '`euler_from_quaternion` of one sample as an ndarray, a list and a tuple '
                'against the plain-Python `math` formula (exact where it is not: near gimbal '
                'lock, see accuracy.md). Ratio: the time of the first call of the operation (the '
                "package's; for Euler angles, with an ndarray) over this call's, in each "
                'round; below 1, the first call is faster.', '', peers]
        else:
            parts += [('Measured ratios: ' if len(run.ratios) > 1 else 'Measured ratio: ')
                      + ', '.join(_measured_ratios(run, with_target=True)) + '. Its output:',
                      '', '```', run.output.rstrip(), '```']
    return '\n'.join(parts) + '\n'
