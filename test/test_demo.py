"""The README's main job (``./run.sh main``) end to end: scene -> live node -> bag -> summary."""
import re
import subprocess
import sys

import pytest
from rotation_dev.paths import REPOSITORY


@pytest.mark.slow
def test_main_job_replays_the_tumbling_box_through_the_node(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'rotation_dev.demo', '--out', str(tmp_path)],
                            cwd=REPOSITORY, capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    assert re.search(r'Imu messages in the scene bag: 1001', out)
    for name in ('quaternion', 'euler', 'angular_velocity'):
        assert f'/imu/{name}: 1001 messages recorded live (none lost)' in out
        assert re.search(rf'/imu/{name}: live node vs offline convert on 1001 common stamps: '
                         r'identical', out)
    orientation = float(re.search(r'orientation error vs truth: max (\S+) rad', out).group(1))
    assert orientation < 1e-14
    assert float(re.search(r'angular velocity error vs truth: max (\S+) rad/s', out).group(1)) \
        < 1e-12
    for png in ('euler.png', 'angular_velocity.png'):
        assert (tmp_path / png).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
