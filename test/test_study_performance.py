"""Tests of rotation_dev.study.performance: benchmark ratios read and judged by their targets."""
import os
import re

import pytest
from rotation_dev.paths import BENCHMARKS_DIR
from rotation_dev.study import performance

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

# The ratio lines as the scripts print them (bench_node: median; bench_bag_convert: both).
NODE_OUTPUT = ('  median ratio rotation_node / relay = 0.920 (spread 0.905 to 0.936; '
               'target <= 1.0)\n')
BAG_OUTPUT = ('ratio naive/ours: 7.76x (target >= 10x); ours/floor: 1.01x (target <= 2x); '
              'per message/ours: 1.76x\n')


def _script(benchmark):
    with open(os.path.join(BENCHMARKS_DIR, benchmark.script)) as stream:
        return stream.read()


@pytest.mark.parametrize('benchmark', performance.BENCHMARKS, ids=lambda b: b.key)
def test_every_target_is_the_one_its_benchmark_script_states(benchmark):
    source = _script(benchmark)
    targets = ([ratio.target for ratio in benchmark.ratios] if benchmark.ratios
               else [f'<= {performance.SINGLE_SAMPLE_TARGET:.2f}'])
    for target in targets:
        assert f'target {target}' in source, (benchmark.script, target)
    stated = set(re.findall(r'target ([<>]= [0-9.]+)', source))
    for ratio in benchmark.ratios:
        assert ratio.target in stated


def test_the_bag_benchmark_is_judged_by_both_of_its_ratios():
    assert [r.target for r in performance.BAG.ratios] == ['>= 10', '<= 2']
    assert performance.read_ratios(performance.BAG, BAG_OUTPUT) == (7.76, 1.01)
    assert performance.read_ratios(performance.BAG, 'ratio naive/ours: 12.0x\n') is None
    assert performance.read_ratios(performance.NODE, NODE_OUTPUT) == (0.92,)


def test_the_summary_says_which_target_each_ratio_met():
    runs = [performance.BenchmarkRun(performance.LIBRARY, 'library', 'not run', detail='quick'),
            performance.BenchmarkRun(performance.NODE, 'node', 'measured', 1.0, NODE_OUTPUT,
                                     ratios=(0.92,)),
            performance.BenchmarkRun(performance.BAG, 'bag', 'measured', 1.0, BAG_OUTPUT,
                                     ratios=(7.76, 1.01))]
    text = performance.performance_markdown(runs, quick=False, command='study',
                                            environment='here')
    bag_row = next(line for line in text.splitlines() if line.startswith('| Bag converter'))
    assert '**7.760** naive / ours (target **missed**)' in bag_row
    assert '**1.010** ours / floor (target met)' in bag_row
    assert 'naive / ours >= 10, ours / floor <= 2' in bag_row
    node_row = next(line for line in text.splitlines() if line.startswith('| Node'))
    assert '**0.920** (target met) | <= 1.0 |' in node_row
    assert 'single sample <= 0.10, batch speed-up >= 2 (>= 3 Euler)' in text
