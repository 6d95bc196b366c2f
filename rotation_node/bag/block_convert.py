"""
``rotation_bag convert``'s conversion of one input topic, block by block.

A :class:`TopicConverter` turns the messages of one converted topic into
the CDR data of their outputs. Where the parameters, the input type and every
output have a block form (:func:`block_form_missing`), it decodes a block of
messages into arrays (:mod:`rotation_node.bag.block_codec`), converts them with
one library call per conversion
(:meth:`rotation_node.pipeline.ConversionPipeline.process_block`) and encodes
each output for the whole block; otherwise, and for any block the block form
cannot read exactly as the per-message path does, it runs the same pipeline
message by message, as the live node does. Either way the output bytes, the
counters and the per-stream state are the per-message form's.

:func:`converted_blocks` reads the input in blocks of :data:`BLOCK_MESSAGES`
messages (all topics, log-time order) and gives each message with its
outputs, in order: the output bag is written as the per-message conversion
writes it, and memory holds one block.
"""
from __future__ import annotations

import contextlib
import gc
import itertools
from typing import Any, Dict, Iterable, Iterator, List, NamedTuple, Optional, Tuple, TYPE_CHECKING

from rotation_node import pipeline, registry
from rotation_node.bag.block_codec import block_encoder, InputBlockDecoder, OutputBlockEncoder
from rotation_node.pipeline import BLOCK_SAMPLES, ConversionPipeline
from rotation_node.wire.cdr import fixed_layout_codec

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

#: Messages read per block (of all topics together).
BLOCK_MESSAGES = BLOCK_SAMPLES

#: Allocations between the cyclic collector's youngest-generation passes while converting.
DEFERRED_COLLECTION_THRESHOLD = 50_000

#: ``(output topic, type name, CDR data)`` of one output message.
Output = Tuple[str, str, bytes]


class _BlockForm(NamedTuple):
    """What a topic converted in blocks uses: the decoder, the output encoders."""

    decoder: InputBlockDecoder
    encoders: List[OutputBlockEncoder]   # one per output, in the order of ``outputs``


@contextlib.contextmanager
def collections_deferred() -> Iterator[None]:
    """
    Run the block with the cyclic garbage collector's passes made rarer; restore them after.

    Reading and writing a bag allocates a few short-lived objects per message
    (the mcap library's records), freed by reference counting; the collector's
    default pass every 700 allocations found nothing to collect in them, and
    cost a sixth of the conversion time (measured by ``bench_bag_convert.py``).
    Garbage in reference cycles is still collected, every
    :data:`DEFERRED_COLLECTION_THRESHOLD` allocations.
    """
    threshold = gc.get_threshold()
    gc.set_threshold(max(threshold[0], DEFERRED_COLLECTION_THRESHOLD), *threshold[1:])
    try:
        yield
    finally:
        gc.set_threshold(*threshold)


def block_form_missing(params: NodeParameters) -> Optional[str]:
    """
    Return why a topic of the parameters' input type is converted message by message, or None.

    The one place that decides it: the pipeline's block form
    (:func:`rotation_node.pipeline.block_form_missing`: input type, frames,
    values, outputs), a fixed CDR layout of the input type, and a block
    encoder for every output message type.
    """
    reason = pipeline.block_form_missing(params)
    if reason is not None:
        return reason
    input_type = registry.INPUTS[params.input_type]
    if fixed_layout_codec(input_type.type_name) is None:
        return f'{input_type.type_name} has no fixed CDR layout'
    for name in params.outputs:
        if block_encoder(registry.OUTPUTS[name].message) is None:
            return f'output {name} ({registry.OUTPUTS[name].type_name}) has no block encoding'
    return None


class TopicConverter:
    """
    Convert the messages of one input topic into their outputs' CDR data.

    Parameters
    ----------
    params : rotation_node.parameters.NodeParameters
    outputs : dict
        ``{output name: (output topic, type name, encode)}`` for every name in
        ``params.outputs``, ``encode(header, numbers) -> bytes`` the output's
        per-message encoder.
    blocks : bool, optional
        Convert in blocks where the parameters allow it (default); False
        converts message by message (the reference the block form is checked
        against).

    Attributes
    ----------
    pipeline : ConversionPipeline
        The topic's pipeline: its ``stats`` count every message, whichever way
        it was converted.
    block_form_missing : str or None
        Why this topic is converted message by message (None: in blocks).

    """

    def __init__(self, params: NodeParameters, outputs: Dict[str, tuple], *, blocks: bool = True):
        self.pipeline = ConversionPipeline(params)
        self._outputs = [(name, *outputs[name]) for name in params.outputs]
        self._by_name = {name: output for name, *output in self._outputs}
        input_type = registry.INPUTS[params.input_type]
        codec = fixed_layout_codec(input_type.type_name)
        self._decode = None if codec is None else codec.decode
        self.block_form_missing = block_form_missing(params) if blocks else 'blocks disabled'
        self._blocks: Optional[_BlockForm] = None
        if self.block_form_missing is None:
            self._blocks = _BlockForm(
                InputBlockDecoder(input_type, self.pipeline.reads_angular_velocity),
                [OutputBlockEncoder(registry.OUTPUTS[name].message) for name in params.outputs])

    def convert(self, records: List, input_topics: Optional[List[str]] = None
                ) -> List[List[Output]]:
        """
        Return the outputs of each record (a :class:`~rotation_node.bag.records.BagMessage`).

        ``input_topics`` names, for each record, the input type's topic it came
        on (for input types with several topics); ``input`` by default.

        Raises
        ------
        BagError
            If a message is not a valid message of the input type (raised
            where the per-message conversion raises it).

        """
        if self._blocks is not None and len(records) > 1:   # a plain type: one topic
            converted = self._converted_block(self._blocks, records)
            if converted is not None:
                return converted
        if input_topics is None:
            input_topics = [registry.INPUT_TOPIC.name] * len(records)
        return [self._converted_message(record, topic)
                for record, topic in zip(records, input_topics)]

    def convert_values(self, records: List, input_topics: Optional[List[str]] = None
                       ) -> List[List[Tuple[str, Any, Any]]]:
        """
        Return the outputs of each record as numbers: ``[(output name, header, numbers)]``.

        What :meth:`convert` encodes, before encoding (``rotation_bag export``):
        the same block or per-message conversion, counters and state. Outputs
        of one sample share its ``header`` object (a read-only view).
        """
        if self._blocks is not None and len(records) > 1:
            converted = self._block_values(self._blocks, records)
            if converted is not None:
                return converted
        if input_topics is None:
            input_topics = [registry.INPUT_TOPIC.name] * len(records)
        return [self.pipeline.process_values(record.message(self._decode), topic)
                for record, topic in zip(records, input_topics)]

    def _block_values(self, blocks: _BlockForm, records: List
                      ) -> Optional[List[List[Tuple[str, Any, Any]]]]:
        decoded = blocks.decoder.decode([record.data for record in records])
        if decoded is None:
            return None
        converted = self.pipeline.process_block(decoded[0])
        if converted is None:
            return None
        result: List[List[Tuple[str, Any, Any]]] = [[] for _ in records]
        headers: Dict[int, Any] = {}
        for name, *_ in self._outputs:
            present = converted.present[name]
            for index, numbers in zip(present.nonzero()[0].tolist(), converted.numbers[name]):
                header = headers.get(index)
                if header is None:
                    header = headers[index] = records[index].message(self._decode).header
                result[index].append((name, header, numbers))
        return result

    def _converted_message(self, record, input_topic) -> List[Output]:
        outputs, result = self._by_name, []
        for name, header, values in self.pipeline.process_values(
                record.message(self._decode), input_topic):
            topic, type_name, encode = outputs[name]
            result.append((topic, type_name, encode(header, values)))
        return result

    def _converted_block(self, blocks: _BlockForm, records: List
                         ) -> Optional[List[List[Output]]]:
        decoded = blocks.decoder.decode([record.data for record in records])
        if decoded is None:
            return None
        block, headers = decoded
        converted = self.pipeline.process_block(block)
        if converted is None:
            return None
        result: List[List[Output]] = [[] for _ in records]
        for (name, topic, type_name, _), encoder in zip(self._outputs, blocks.encoders):
            present = converted.present[name]
            datas = encoder.encode(headers, present, converted.numbers[name])
            for index, data in zip(present.nonzero()[0].tolist(), datas):
                result[index].append((topic, type_name, data))
        return result


def converted_blocks(records: Iterable, converters: Dict[str, TopicConverter],
                     routes: Optional[Dict[str, Tuple[str, str]]] = None
                     ) -> Iterator[List[Tuple[Any, Optional[List[Output]]]]]:
    """
    Give the records in blocks, each record with the outputs of its stream's converter.

    Parameters
    ----------
    records : iterable of BagMessage
        The input, in the order it is to be written.
    converters : dict
        ``{stream: TopicConverter}``; records of other topics get None.
    routes : dict, optional
        ``{bag topic: (stream, the input type's topic name)}``; by default
        each converter's stream is one bag topic of that name (a plain input
        type's ``input``).

    Yields
    ------
    list of (BagMessage, list of Output or None)
        One block of at most :data:`BLOCK_MESSAGES` records, in input order;
        None for a record of no converted stream.

    """
    if routes is None:
        routes = {topic: (topic, registry.INPUT_TOPIC.name) for topic in converters}
    records = iter(records)
    while True:
        block = list(itertools.islice(records, BLOCK_MESSAGES))
        if not block:
            return
        outputs: List[Optional[List[Output]]] = [None] * len(block)
        by_stream: Dict[str, Tuple[List[int], List[str]]] = {}
        for index, record in enumerate(block):
            route = routes.get(record.topic)
            if route is not None:
                indices, names = by_stream.setdefault(route[0], ([], []))
                indices.append(index)
                names.append(route[1])
        for stream, (indices, names) in by_stream.items():
            converted = converters[stream].convert([block[i] for i in indices], names)
            for index, result in zip(indices, converted):
                outputs[index] = result
        yield list(zip(block, outputs))
