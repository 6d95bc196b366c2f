"""Tests of rotation_node.bag.plot: PNGs of converted topics."""
import os

import matplotlib.image
import numpy as np
import pytest
from bag_helpers import imu_messages, stamp_ns
from std_msgs.msg import String

from rotation_node.bag.convert import convert
from rotation_node.bag.mcap_io import BagWriter
from rotation_node.bag.plot import plot_topic
from rotation_node.errors import BagError
from rotation_node.parameters import OUTPUTS, NodeParameters

PARAMS = NodeParameters(input_type='imu', outputs=OUTPUTS, euler_sequence='ZYX',
                        euler_degrees=True)


@pytest.fixture(scope='module')
def converted(tmp_path_factory):
    """A bag with /imu and every output of the node, converted from 200 messages."""
    directory = tmp_path_factory.mktemp('plot')
    source, output = directory / 'imu.mcap', directory / 'converted.mcap'
    with BagWriter(source) as writer:
        for msg in imu_messages(np.random.default_rng(5), 200):
            writer.write('/imu', msg, stamp_ns(msg))
        writer.write('/text', String(data='not plottable'), stamp_ns(msg))
    convert(source, output, PARAMS)
    return output


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


def test_refuses_to_overwrite(tmp_path, converted):
    png = tmp_path / 'plot.png'
    png.write_bytes(b'old')
    with pytest.raises(BagError, match='plot.png already exists'):
        plot_topic(converted, '/imu/euler', png)
    assert png.read_bytes() == b'old'
    plot_topic(converted, '/imu/euler', png, overwrite=True)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
