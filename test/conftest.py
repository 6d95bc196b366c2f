"""
Test-session set-up shared by all test modules.

ROS isolation: every pytest run gets its own ``ROS_DOMAIN_ID`` (derived from the
process id, within the range that is valid for localhost discovery) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, set in ``os.environ`` before any
test starts so that subprocesses started by tests inherit them.
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

if 'ROTATION_NODE_TEST_DOMAIN_ID' not in os.environ:
    os.environ['ROTATION_NODE_TEST_DOMAIN_ID'] = str(1 + os.getpid() % 100)
os.environ['ROS_DOMAIN_ID'] = os.environ['ROTATION_NODE_TEST_DOMAIN_ID']
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
