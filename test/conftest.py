"""
Test-session set-up shared by all test modules.

ROS isolation: every pytest run gets its own ``ROS_DOMAIN_ID`` (derived from the
process id, within the range that is valid for localhost discovery; one per
pytest-xdist worker) and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, set in
``os.environ`` before any test starts so that subprocesses started by tests
inherit them.
"""
import os
import sys

from hypothesis import settings
import pytest

# CI runs the same examples every time (a new random counterexample must not
# turn an unrelated change red); locally every run explores new ones.
settings.register_profile('ci', derandomize=True, deadline=None, print_blob=True)
if os.environ.get('CI'):
    settings.load_profile('ci')


def _domain_id():
    """
    Return this test process's ROS domain: the run's, or under pytest-xdist one per worker.

    The run's domain (``ROTATION_NODE_TEST_DOMAIN_ID``, else from the process id) is set
    in the environment the xdist workers inherit; worker ``gwN`` takes the N+1-th domain
    after it, so that no two workers see each other's nodes. Domains 1..101 are valid
    with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.
    """
    run = int(os.environ.setdefault('ROTATION_NODE_TEST_DOMAIN_ID', str(1 + os.getpid() % 101)))
    worker = os.environ.get('PYTEST_XDIST_WORKER')   # 'gw0', 'gw1', ...
    if worker is None:
        return run
    return 1 + (run + int(worker[2:])) % 101


os.environ['ROS_DOMAIN_ID'] = str(_domain_id())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')

sys.path.insert(0, os.path.dirname(__file__))
# The development tools of the checkout (rotation_dev: hard cases, study, demo).
sys.path.append(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture
def rng():
    """Seeded generator: every random test is reproducible."""
    import numpy as np
    return np.random.default_rng(20261121)


def pytest_collection_modifyitems(config, items):
    """
    Under pytest-xdist, run the modules whose every test is slow first, then those with most.

    run.sh sends whole modules to the workers (``--dist loadscope``: a module-scoped
    fixture, such as a converted bag or a built package, is made once) in this order
    (``--no-loadscope-reorder``), so that no long module starts last while the other
    workers are idle. The modules of slow tests only (processes, builds, the linters, the
    study) are the long ones, also when they hold a single test: xdist gives a worker its
    next module as soon as two of its tests are left, so two such modules at the end
    would queue on one worker.
    """
    if os.environ.get('PYTEST_XDIST_WORKER') is None:
        return
    slow, tests = {}, {}
    for item in items:
        module = item.module.__name__
        slow[module] = slow.get(module, 0) + (item.get_closest_marker('slow') is not None)
        tests[module] = tests.get(module, 0) + 1

    def rank(item):
        module = item.module.__name__
        return (slow[module] < tests[module], -slow[module])

    items.sort(key=rank)   # stable: within a module as it was
