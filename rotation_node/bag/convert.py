"""
Convert a recorded bag offline with the node's conversions (``rotation_bag convert``).

The output holds every input message unchanged (schema and metadata as stored, ROS 2 names)
plus, for each converted topic ``T``, what the live node would publish on ``T/<output>``:
one pipeline per topic (``T`` with ``T_static`` for ``tf``) fed in log-time order, each
output with the times of its input message. Streamed, in blocks where it can be
(:mod:`~rotation_node.bag.block_convert`), with the node's results bit for bit.
"""
from __future__ import annotations

import os
from typing import Any, Callable, Dict, List, Optional, Sequence, TextIO, TYPE_CHECKING

from rotation_node import registry
from rotation_node.bag.block_convert import collections_deferred, converted_blocks, TopicConverter
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.command_line.progress import ProgressBar
from rotation_node.command_line.stop_signal import raise_if_stopped
from rotation_node.errors import BagError
from rotation_node.static_mounting import resolved_from_bag
from rotation_node.wire.qos_yaml import output_qos_yaml

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters
    from rotation_node.pipeline import PipelineStats
    from rotation_node.type_aliases import StrPath


def output_topic(input_topic: str, output_name: str) -> str:
    """Topic of the output ``output_name`` of ``input_topic``: ``/imu`` -> ``/imu/euler``."""
    return f'{input_topic.rstrip("/")}/{output_name}'


def input_streams(reader: Any, input_type: registry.InputType,
                  topics: Optional[Sequence[str]]) -> Dict[str, Dict[str, str]]:
    """
    Return the streams to convert: ``{topic: {bag topic: the input type's topic name}}``.

    A stream is named by its first topic: the given ones, checked, or every topic of the
    input type that is no other's companion (``T_static`` beside ``T``, by the suffix of
    the input type's other topic names to its first).
    """
    first, *others = input_type.topics
    type_name = input_type.type_name

    def companions(topic):
        return {topic + other.name[len(first.name):]: other.name for other in others
                if other.name.startswith(first.name)}

    if topics is None:
        candidates = [topic for topic, name in reader.topics.items() if name == type_name]
        companion_topics = {c for topic in candidates for c in companions(topic)}
        topics = [topic for topic in candidates if topic not in companion_topics]
        if not topics:
            raise BagError(f'{reader.path} has no {type_name} topic to convert '
                           f'(its topics: {reader.topics})')
    else:
        topics = [reader.topic_name(topic) for topic in topics]   # raises if not in the bag
        for topic in topics:
            if reader.topics[topic] != type_name:
                raise BagError(f'topic {topic} in {reader.path} is {reader.topics[topic]}, '
                               f'but input_type expects {type_name}')
    streams = {}
    for topic in dict.fromkeys(topics):
        streams[topic] = {topic: first.name}
        for companion, name in companions(topic).items():
            if reader.topics.get(companion) == type_name:
                streams[topic][companion] = name
    return streams


def check_output(input_path: StrPath, output_path: StrPath) -> None:
    """Refuse an output that is the input bag, inside it, or replaces the directory holding it."""
    if os.path.exists(output_path) and os.path.samefile(input_path, output_path):
        raise BagError(f'output {output_path} is the input bag')
    real_input, real_output = os.path.realpath(input_path), os.path.realpath(output_path)
    if real_input.startswith(real_output + os.sep):
        raise BagError(f'output {output_path} holds the input bag {input_path}')
    if os.path.isdir(input_path) and real_output.startswith(real_input + os.sep):
        raise BagError(f'output {output_path} is inside the input bag {input_path}')


def convert(input_path: StrPath, output_path: StrPath, params: NodeParameters, *,
            topics: Optional[Sequence[str]] = None, overwrite: bool = False,
            compression: Optional[str] = None, progress_stream: Optional[TextIO] = None,
            strict: bool = False, report: Optional[Callable[[str], None]] = None,
            blocks: bool = True) -> Dict[str, PipelineStats]:
    """
    Write ``output_path``: the input bag plus the node's outputs for its input topics.

    Parameters
    ----------
    input_path : str or os.PathLike
        Any bag :func:`rotation_node.bag.reading.reader.open_bag` reads; only read.
    output_path : str or os.PathLike
        The output bag, a rosbag2 directory or a single MCAP file if it ends
        in ``.mcap``. It is written as ``<output>.part`` and renamed when
        complete; a failure or a signal removes it.
    params : rotation_node.parameters.NodeParameters
        As loaded from the node's parameters file.
    topics : list of str, optional
        Topics to convert (their names in the bag or their ROS 2 names); by
        default every topic of the type ``params.input_type`` names (for a type
        with several topics, the first of each group: ``/tf``, not ``/tf_static``).
    overwrite : bool, optional
        Replace an existing output (atomically, once the new one is complete).
    compression : str, optional
        Chunk compression of the output, ``'zstd'``, ``'lz4'`` or ``'none'``;
        the input's by default.
    progress_stream : file, optional
        Where to draw the progress bar (only if it is a terminal); stderr by default.
    strict : bool, optional
        Refuse an unfinished recording or a damaged MCAP file instead of
        converting what it holds.
    report : callable, optional
        ``report(line)`` receives what the input is (``<path>: rosbag2
        directory (mcap, 3 files), 5000 messages``) and its notes (an
        unfinished recording, a renamed topic) once it is opened, before
        anything is written; then what reading found could not be read.
    blocks : bool, optional
        Convert in blocks where the parameters allow it (the default; see
        :mod:`rotation_node.bag.block_convert`); False converts message by
        message. The output is the same byte for byte.

    Returns
    -------
    dict
        ``{input topic: PipelineStats}``.

    Raises
    ------
    BagError
        If the input is unreadable or corrupt, a topic is missing or of the
        wrong type, an output topic already exists in the input, or the output
        exists (without ``overwrite``), is being written by another process
        (``<output>.part`` exists) or is the input; a ``DiskFullError`` if the
        disk fills (no output is left then).

    """
    with open_bag(input_path, strict=strict) as reader:
        check_output(input_path, output_path)
        reader.report_contents(report)
        with reader.reporting_new_notes(report):
            params = resolved_from_bag(reader, params)   # the mounting from /tf_static, if asked
            input_type = registry.INPUTS[params.input_type]
            streams = input_streams(reader, input_type, topics)
            # {bag topic: (its stream's first topic, the input type's name for it)}
            routes = {bag_topic: (topic, name) for topic, stream in streams.items()
                      for bag_topic, name in stream.items()}
            encoders = {name: (registry.OUTPUTS[name].type_name,
                               registry.OUTPUTS[name].message.encoder())
                        for name in params.outputs}
            # {input topic: {output name: (output topic, type name, encode)}}
            outputs = {topic: {name: (output_topic(topic, name), *encoder)
                               for name, encoder in encoders.items()}
                       for topic in streams}
            converters = {topic: TopicConverter(params, outputs[topic], blocks=blocks)
                          for topic in streams}
            offered_qos = output_qos_yaml(params)
            new_topics = [TopicMetadata(output_topic_name, type_name, offered_qos)
                          for topic_outputs in outputs.values()
                          for output_topic_name, type_name, _ in topic_outputs.values()]
            clashes = [t.name for t in new_topics if t.name in reader.topics]
            if clashes:
                raise BagError(f'output topic {", ".join(clashes)} is already in {reader.path}')

            compression = reader.compression if compression is None else compression
            writing = BagWriter(output_path, overwrite=overwrite, compression=compression)
            with collections_deferred(), writing as writer, \
                    ProgressBar(sum(reader.message_counts.values()), stream=progress_stream,
                                label='converting ') as progress:
                for metadata in [*reader.topic_metadata.values(), *new_topics]:
                    writer.add_topic(metadata)
                converted_input = converted_blocks(reader.messages(), converters, routes)
                while True:
                    try:
                        block = next(converted_input, None)
                    except BagError as error:   # a message that cannot be decoded names no file
                        raise reader.naming_this_bag(error) from None
                    if block is None:
                        break
                    raise_if_stopped()
                    written: List[tuple] = []
                    add = written.append
                    for record, converted in block:
                        log_time_ns, publish_time_ns = record.log_time_ns, record.publish_time_ns
                        add((record.topic, record.type_name, record.data, log_time_ns,
                             publish_time_ns))
                        if converted:
                            for topic, type_name, data in converted:
                                add((topic, type_name, data, log_time_ns, publish_time_ns))
                    writer.write_serialized_block(written)
                    progress.update(len(block))
                raise_if_stopped()   # the last chance before the output is committed
    return {topic: converter.pipeline.stats for topic, converter in converters.items()}
