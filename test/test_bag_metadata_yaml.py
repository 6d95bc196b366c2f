"""Tests of rotation_node.bag.metadata_yaml: libyaml's text is PyYAML's, for bag metadata."""
import os

from rotation_node.bag import metadata_yaml
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter
import yaml


def _metadata(tmp_path):
    """Return the metadata of a written bag: QoS, type hashes, odd topic names and strings."""
    with BagWriter(tmp_path / 'bag', compression='none') as writer:
        writer.add_topic(TopicMetadata('/imu', 'sensor_msgs/msg/Imu',
                                       '- history: keep_last\n  depth: 10'))
        writer.add_topic(TopicMetadata('/odd: "name" # not a comment', 'std_msgs/msg/String',
                                       definition='string data', type_hash='yes'))
        writer.add_topic(TopicMetadata('/ünïcode', 'std_msgs/msg/String'))
        writer.write_serialized('/odd: "name" # not a comment', 'std_msgs/msg/String',
                                b'\0\1\0\0\1\0\0\0\0', 17)
        metadata = writer.rosbag2_metadata()
    metadata['custom_data'] = {'empty': '', 'null': None, 'long': 'word ' * 40, 'true': 'true'}
    return metadata


def test_dump_is_pyyamls(tmp_path):
    metadata = _metadata(tmp_path)
    assert metadata_yaml.dump(metadata) == yaml.safe_dump(metadata, sort_keys=False)
    document = {'rosbag2_bagfile_information': metadata}
    assert metadata_yaml.dump(document) == yaml.safe_dump(document, sort_keys=False)


def test_load_is_pyyamls(tmp_path):
    text = yaml.safe_dump(_metadata(tmp_path), sort_keys=False)
    assert metadata_yaml.load(text) == yaml.safe_load(text)
    with open(tmp_path / 'bag' / 'metadata.yaml', encoding='utf-8') as stream:
        written = metadata_yaml.load(stream)
    with open(tmp_path / 'bag' / 'metadata.yaml', encoding='utf-8') as stream:
        assert written == yaml.safe_load(stream)
    assert os.path.basename(written['rosbag2_bagfile_information']['relative_file_paths'][0]) \
        == 'bag_0.mcap'


def test_uses_libyaml_where_pyyaml_has_it():
    assert metadata_yaml._DUMPER is (yaml.CSafeDumper if yaml.__with_libyaml__
                                     else yaml.SafeDumper)
