"""Tests of rotation_node.bag.plot: PNGs of converted topics and of input topics."""
import math
import operator
import os

from bag_helpers import imu_messages, stamp_ns
import matplotlib.image
import numpy as np
import pytest
from ros_harness import make_input_message
from rotation_node import registry
from rotation_node.bag.convert import convert
from rotation_node.bag.plot import output_panels, plot_series, plot_topic
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters, OUTPUTS
from scipy.spatial.transform import Rotation
from std_msgs.msg import String

T0 = 1_700_000_000_000_000_000
PARAMS = NodeParameters(input_type='imu', outputs=OUTPUTS, euler_sequence='ZYX',
                        euler_degrees=True)


@pytest.fixture(scope='module')
def converted(tmp_path_factory):
    """Return a bag with /imu and every output of the node, converted from 200 messages."""
    directory = tmp_path_factory.mktemp('plot')
    source, output = directory / 'imu.mcap', directory / 'converted.mcap'
    with BagWriter(source) as writer:
        for msg in imu_messages(np.random.default_rng(5), 200):
            writer.write('/imu', msg, stamp_ns(msg))
        writer.write('/text', String(data='not plottable'), stamp_ns(msg))
    convert(source, output, PARAMS)
    return output


@pytest.mark.slow
@pytest.mark.parametrize('topic, panels', [
    ('/imu', 2),
    *[(f'/imu/{name}', 2 if name in ('axis_angle', 'euler_covariance') else 1)
      for name in OUTPUTS]])
def test_plots_every_output(tmp_path, converted, topic, panels):
    png = tmp_path / 'plot.png'
    assert plot_topic(converted, topic, png, params=PARAMS) == 200
    image = matplotlib.image.imread(png)
    height, width, _ = image.shape
    assert width == 1100 and height == round(110 * (3.2 * panels + 0.6))
    assert image[..., :3].std() > 0.05   # lines were drawn, not a blank canvas
    assert os.listdir(tmp_path) == ['plot.png']


@pytest.mark.parametrize('topic, match', [
    ('/nope', '/nope not in'),
    ('/text', 'cannot plot std_msgs/msg/String'),
])
def test_bad_topic_leaves_no_file(tmp_path, converted, topic, match):
    with pytest.raises(BagError, match=match):
        plot_topic(converted, topic, tmp_path / 'plot.png')
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
def test_refuses_to_overwrite(tmp_path, converted):
    png = tmp_path / 'plot.png'
    png.write_bytes(b'old')
    with pytest.raises(BagError, match='plot.png already exists'):
        plot_topic(converted, '/imu/euler', png)
    assert png.read_bytes() == b'old'
    plot_topic(converted, '/imu/euler', png, overwrite=True)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


PLAIN_INPUTS = [name for name, entry in registry.INPUTS.items() if entry.stream is None]


@pytest.mark.slow
@pytest.mark.parametrize('input_type', PLAIN_INPUTS)
def test_every_input_type_is_drawn_as_euler_angles_with_gaps(tmp_path, rng, input_type):
    """The orientation of any input, as Euler angles (scipy), NaN where unknown or invalid."""
    params = NodeParameters(input_type=input_type, euler_sequence='ZYX', euler_degrees=True)
    rotations = Rotation.random(40, random_state=rng)
    omegas = rng.normal(size=(40, 3))
    msgs = [make_input_message(input_type, rotation, omega=omega, stamp_ns=T0 + i * 10**7,
                               sequence='ZYX', degrees=True)
            for i, (rotation, omega) in enumerate(zip(rotations, omegas))]
    entry = registry.INPUTS[input_type]
    orientation = operator.attrgetter(entry.orientation_field)
    orientation(msgs[3]).x = math.nan   # invalid
    gaps = {3}
    if entry.orientation_form == registry.QUATERNION:
        target = orientation(msgs[7])
        target.x = target.y = target.z = target.w = 0.0   # a zero quaternion
        gaps.add(7)
    if input_type == 'imu':
        msgs[11].orientation_covariance[0] = -1.0   # orientation unknown
        msgs[12].angular_velocity_covariance[0] = -1.0   # angular velocity unknown
        gaps.add(11)
    path = tmp_path / 'in.mcap'
    with BagWriter(path) as writer:
        for msg in msgs:
            writer.write('/in', msg, stamp_ns(msg))
    with open_bag(path) as bag:
        times, panels, values = plot_series(bag, '/in', params)
    assert list(times) == [stamp_ns(msg) for msg in msgs]
    assert panels[0].title == 'Orientation as Euler angles, sequence ZYX (intrinsic)'
    assert panels[0].unit == 'deg'
    known = [i for i in range(40) if i not in gaps]
    assert np.isnan(values[0][sorted(gaps)]).all() and not np.isnan(values[0][known]).any()
    difference = values[0][known] - rotations[known].as_euler('ZYX', degrees=True)
    assert np.abs((difference + 180.0) % 360.0 - 180.0).max() < 1e-9
    if entry.angular_velocity_field is None:
        assert len(panels) == 1
    else:
        assert panels[1].title == 'Angular velocity' and len(panels) == 2
        rates_known = [i for i in range(40) if i != 12 or input_type != 'imu']
        assert np.array_equal(values[1][rates_known], omegas[rates_known])
        assert np.isnan(values[1][12]).all() == (input_type == 'imu')
    png = tmp_path / 'plot.png'
    assert plot_topic(path, '/in', png, params=params) == 40
    assert matplotlib.image.imread(png)[..., :3].std() > 0.05


def _numbers_count(output):
    if output.message.layout is not None:
        return output.message.layout.dim[0].stride
    return len(output.message.numbers(output.message_class()))


@pytest.mark.parametrize('name', OUTPUTS)
def test_each_output_plots_every_number_once(name):
    output = registry.OUTPUTS[name]
    params = NodeParameters(euler_sequence='ZXZ', euler_degrees=True)
    drawn = [index for panel in output_panels(name, params)
             for index in range(panel.start, panel.start + len(panel.labels))]
    assert drawn == list(range(_numbers_count(output)))
