"""
Where the test suite spends its CPU time: a pytest plugin and its summary.

Record (each worker writes one file into DIR, a line per test: its module, worker,
wall start and end, the CPU time of the test process and of the child processes it
waited for, set-up and tear-down of its fixtures included)::

    PYTHONPATH=$PWD .venv/bin/python -m pytest -p tools.suite_profile --suite-profile=DIR
        [-n 2 --dist loadscope --no-loadscope-reorder] [-m "not slow"] [FILES]

Summarize (CPU per module and per test, and each worker's timeline of modules)::

    .venv/bin/python tools/suite_profile.py DIR [--tests 30]

Compare CPU seconds, not wall times: on a shared machine the wall time of one test
says how busy the machine was as much as what the test costs.
"""
import argparse
import collections
import json
import os
import resource
import time

import pytest


def _children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def pytest_addoption(parser):
    parser.addoption('--suite-profile', metavar='DIR', default=None,
                     help="write each test's CPU time and wall interval into DIR "
                          '(tools/suite_profile.py)')


class _Recorder:
    def __init__(self, directory):
        os.makedirs(directory, exist_ok=True)
        worker = os.environ.get('PYTEST_XDIST_WORKER', 'main')
        self._worker = worker
        self._file = open(os.path.join(directory, f'{worker}.jsonl'), 'a')
        self._failed = set()
        self._write({'event': 'start', 'worker': worker, 'wall': time.time(),
                     'cpu': time.process_time(), 'children': _children_cpu()})

    def _write(self, record):
        self._file.write(json.dumps(record) + '\n')
        self._file.flush()

    def pytest_collection_finish(self, session):
        self._write({'event': 'collected', 'worker': self._worker, 'wall': time.time(),
                     'cpu': time.process_time(), 'children': _children_cpu()})

    def pytest_runtest_logreport(self, report):
        if report.failed:
            self._failed.add(report.nodeid)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item, nextitem):
        wall, cpu, children = time.time(), time.process_time(), _children_cpu()
        yield
        self._write({'event': 'test', 'worker': self._worker, 'nodeid': item.nodeid,
                     'module': item.nodeid.split('::')[0],
                     'slow': item.get_closest_marker('slow') is not None,
                     'failed': item.nodeid in self._failed,
                     'start': wall, 'end': time.time(),
                     'cpu': time.process_time() - cpu,
                     'children': _children_cpu() - children})

    def pytest_sessionfinish(self, session):
        self._write({'event': 'finish', 'worker': self._worker, 'wall': time.time(),
                     'cpu': time.process_time(), 'children': _children_cpu()})
        self._file.close()


def pytest_configure(config):
    directory = config.getoption('--suite-profile')
    if directory:
        config.pluginmanager.register(_Recorder(directory), 'suite_profile_recorder')


def _records(directory):
    for name in sorted(os.listdir(directory)):
        if name.endswith('.jsonl'):
            with open(os.path.join(directory, name)) as lines:
                for line in lines:
                    yield json.loads(line)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('directory')
    parser.add_argument('--tests', type=int, default=30, help='how many tests to list')
    parser.add_argument('--modules', type=int, default=40, help='how many modules to list')
    args = parser.parse_args(argv)
    records = list(_records(args.directory))
    tests = [r for r in records if r['event'] == 'test']
    modules = collections.defaultdict(lambda: {'cpu': 0.0, 'children': 0.0, 'wall': 0.0,
                                               'tests': 0, 'slow': 0})
    for test in tests:
        module = modules[test['module']]
        module['cpu'] += test['cpu']
        module['children'] += test['children']
        module['wall'] += test['end'] - test['start']
        module['tests'] += 1
        module['slow'] += test['slow']
    total = sum(t['cpu'] + t['children'] for t in tests)
    fast = sum(t['cpu'] + t['children'] for t in tests if not t['slow'])
    print(f'{len(tests)} tests, CPU {total:.1f} s in tests '
          f'({fast:.1f} s in the {sum(not t["slow"] for t in tests)} not slow)')
    by_worker = collections.defaultdict(list)
    for record in records:
        by_worker[record['worker']].append(record)
    for worker, rows in sorted(by_worker.items()):
        start = [r for r in rows if r['event'] == 'start']
        collected = [r for r in rows if r['event'] == 'collected']
        finish = [r for r in rows if r['event'] == 'finish']
        if worker == 'main' and start and finish:
            print(f'run: {finish[-1]["wall"] - start[0]["wall"]:.1f} s wall, '
                  f'{finish[-1]["cpu"] + finish[-1]["children"] - start[0]["cpu"]:.1f} s CPU '
                  f'(pytest and every process it waited for)')
            continue
        if start and collected:
            print(f'{worker}: collection {collected[0]["cpu"] - start[0]["cpu"]:.1f} s CPU, '
                  f'{collected[0]["wall"] - start[0]["wall"]:.1f} s wall', end='')
        if start and finish:
            print(f'; whole worker {finish[-1]["cpu"] + finish[-1]["children"]:.1f} s CPU, '
                  f'{finish[-1]["wall"] - start[0]["wall"]:.1f} s wall', end='')
        print()
    print(f'\n{"module":50} {"CPU s":>7} {"child s":>7} {"wall s":>7} {"tests":>6} {"slow":>5}')
    ranked = sorted(modules.items(), key=lambda kv: -(kv[1]['cpu'] + kv[1]['children']))
    for name, module in ranked[:args.modules]:
        print(f'{name:50} {module["cpu"]:7.1f} {module["children"]:7.1f} {module["wall"]:7.1f} '
              f'{module["tests"]:6d} {module["slow"]:5d}')
    for test in tests:
        if test.get('failed'):
            print(f'failed: {test["nodeid"]} ({test["worker"]})')
    print(f'\n{"test":90} {"CPU s":>7} {"child s":>7} {"wall s":>7}')
    for test in sorted(tests, key=lambda t: -(t['cpu'] + t['children']))[:args.tests]:
        print(f'{test["nodeid"][:90]:90} {test["cpu"]:7.1f} {test["children"]:7.1f} '
              f'{test["end"] - test["start"]:7.1f}')
    if len(by_worker) > 1:
        t0 = min(t['start'] for t in tests)
        print('\nworker timeline (module: start..end, wall seconds from the first test)')
        for worker in sorted(by_worker):
            spans = collections.OrderedDict()
            for test in sorted((t for t in tests if t['worker'] == worker),
                               key=lambda t: t['start']):
                span = spans.setdefault(test['module'], [test['start'], test['end']])
                span[1] = test['end']
            line = ', '.join(f'{name.split("/")[-1][5:-3]} {s - t0:.0f}..{e - t0:.0f}'
                             for name, (s, e) in spans.items() if e - s >= 3)
            print(f'{worker}: {line}')


if __name__ == '__main__':
    main()
