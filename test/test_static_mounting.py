"""Tests of rotation_node.static_mounting: the mounting read once from /tf_static."""
from bag_helpers import imu_messages
from geometry_msgs.msg import TransformStamped
import numpy as np
import pytest
from rotation_node.bag.cli import main
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import ParameterError
from rotation_node.parameters import NodeParameters
from rotation_node.static_mounting import (
    needs_static_mounting, resolved, StaticMountingLookup)
from scipy.spatial.transform import Rotation
from tf2_msgs.msg import TFMessage
import yaml

# base_link -> plate -> imu_link, as a URDF would publish them on /tf_static.
BASE_PLATE = Rotation.from_euler('xyz', [0.0, 0.0, 90.0], degrees=True)
PLATE_IMU = Rotation.from_euler('xyz', [180.0, 10.0, 0.0], degrees=True)
# M: base_link in imu_link = (R_base_imu)^T.
EXPECTED_M = (BASE_PLATE * PLATE_IMU).inv()
FRAMES = {'mounting_tf_sensor_frame': 'imu_link', 'mounting_tf_body_frame': 'base_link'}


def edge(parent, child, rotation):
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(c) for c in rotation.as_quat())
    return msg


def static_message(*edges):
    return TFMessage(transforms=list(edges))


def test_lookup_composes_the_static_chain():
    lookup = StaticMountingLookup(NodeParameters(**FRAMES))
    assert lookup.add(static_message(edge('base_link', 'plate', BASE_PLATE))) is None
    assert 'imu_link' in lookup.problem
    found = lookup.add(static_message(edge('plate', 'imu_link', PLATE_IMU)))
    m = Rotation.from_quat(found.mounting_body_rotation)
    assert (m.inv() * EXPECTED_M).magnitude() < 1e-15
    assert (found.mounting_tf_sensor_frame, found.mounting_tf_body_frame) == ('', '')
    assert not needs_static_mounting(found)


def test_a_transform_tf2_would_ignore_gives_no_mounting():
    """A NaN translation: tf2 ignores the whole transform, so it gives no mounting."""
    lookup = StaticMountingLookup(NodeParameters(**FRAMES))
    broken = edge('base_link', 'imu_link', EXPECTED_M.inv())
    broken.transform.translation.x = float('nan')
    assert lookup.add(static_message(broken)) is None
    assert 'do not exist' in lookup.problem   # the sample never named its frames
    found = lookup.add(static_message(edge('base_link', 'imu_link', EXPECTED_M.inv())))
    m = Rotation.from_quat(found.mounting_body_rotation)
    assert (m.inv() * EXPECTED_M).magnitude() < 1e-15


def test_resolved_keeps_the_other_parameters():
    params = NodeParameters(outputs=('quaternion',), mounting_yaw_offset=0.5, **FRAMES)
    done = resolved(params, [0.0, 0.0, 0.6, 0.8])
    assert done == NodeParameters(outputs=('quaternion',), mounting_yaw_offset=0.5,
                                  mounting_body_rotation=(0.0, 0.0, 0.6, 0.8))


@pytest.mark.parametrize('values, message', [
    ({'mounting_tf_sensor_frame': 'imu_link'},
     "'mounting.tf_body_frame': required with 'mounting.tf_sensor_frame'"),
    ({'mounting_tf_body_frame': 'base_link'},
     "'mounting.tf_sensor_frame': required with 'mounting.tf_body_frame'"),
])
def test_one_frame_alone_is_refused_where_it_is_used(values, message):
    params = NodeParameters(**values)   # ROS sets parameters one at a time
    with pytest.raises(ParameterError, match=message):
        needs_static_mounting(params)


@pytest.mark.parametrize('values, message', [
    ({'mounting_tf_sensor_frame': 'a', 'mounting_tf_body_frame': 'a'}, 'are both'),
    ({**FRAMES, 'mounting_body_rotation': (0.0, 0.0, 90.0)}, 'not both'),
    ({'mounting_tf_sensor_frame': '/imu_link', 'mounting_tf_body_frame': 'b'}, "starts with '/'"),
])
def test_contradictions_are_refused_on_construction(values, message):
    with pytest.raises(ParameterError, match=message):
        NodeParameters(**values)


def write_bag(path, rng, tf_static):
    messages = imu_messages(rng, 20)
    start = messages[0].header.stamp.sec * 10**9 + messages[0].header.stamp.nanosec
    with BagWriter(path) as writer:
        for msg in tf_static:
            writer.write('/tf_static', msg, start - 1)
        for k, msg in enumerate(messages):
            writer.write('/imu', msg, start + k)
    return messages


def params_file(tmp_path, **parameters):
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({'rotation_node': {'ros__parameters': parameters}}))
    return path


def test_convert_reads_the_mounting_from_the_bags_tf_static(tmp_path, rng):
    bag = tmp_path / 'in.mcap'
    messages = write_bag(bag, rng, [static_message(edge('base_link', 'plate', BASE_PLATE)),
                                    static_message(edge('plate', 'imu_link', PLATE_IMU))])
    params = params_file(tmp_path, input_type='imu', outputs=['quaternion'],
                         mounting={'tf_sensor_frame': 'imu_link', 'tf_body_frame': 'base_link'})
    assert main(['convert', str(bag), str(tmp_path / 'out.mcap'), '--params', str(params),
                 '--topic', '/imu']) == 0
    with BagReader(tmp_path / 'out.mcap') as reader:
        got = [m.message().quaternion for m in reader.messages(['/imu/quaternion'])]
    got = Rotation.from_quat([[q.x, q.y, q.z, q.w] for q in got])
    truth = Rotation.from_quat([[m.orientation.x, m.orientation.y, m.orientation.z,
                                 m.orientation.w] for m in messages])
    assert len(got) == 20
    assert ((truth * EXPECTED_M).inv() * got).magnitude().max() < 1e-14
    # export reads it alike.
    assert main(['export', str(bag), str(tmp_path / 'out.csv'), '--params', str(params)]) == 0
    rows = (tmp_path / 'out.csv').read_text().splitlines()[1:]
    q = np.array([[float(x) for x in row.split(',')[2:6]] for row in rows])
    assert ((truth * EXPECTED_M).inv() * Rotation.from_quat(q)).magnitude().max() < 1e-14


@pytest.mark.parametrize('tf_static, message', [
    ([], 'the bag has no /tf_static'),
    ([static_message(edge('base_link', 'plate', BASE_PLATE))],
     "gives no orientation of 'base_link' in 'imu_link'"),
])
def test_missing_transforms_are_one_line_and_nothing_written(tmp_path, rng, capsys,
                                                             tf_static, message):
    bag = tmp_path / 'in.mcap'
    write_bag(bag, rng, tf_static)
    params = params_file(tmp_path, input_type='imu', outputs=['quaternion'],
                         mounting={'tf_sensor_frame': 'imu_link', 'tf_body_frame': 'base_link'})
    for command, out in (('convert', 'out.mcap'), ('export', 'out.csv')):
        assert main([command, str(bag), str(tmp_path / out), '--params', str(params)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert sorted(p.name for p in tmp_path.iterdir()) == ['in.mcap', 'params.yaml']


def test_one_frame_in_a_parameters_file_is_one_line(tmp_path, rng, capsys):
    bag = tmp_path / 'in.mcap'
    write_bag(bag, rng, [])
    params = params_file(tmp_path, input_type='imu', outputs=['quaternion'],
                         mounting={'tf_sensor_frame': 'imu_link'})
    assert main(['convert', str(bag), str(tmp_path / 'out.mcap'), '--params', str(params)]) == 1
    assert "'mounting.tf_body_frame': required" in capsys.readouterr().err
