"""
``rotation_bag convert``'s conversion of one input topic, block by block.

A :class:`TopicConverter` decodes a block of messages into arrays (``block_codec``),
converts them with one library call per conversion and encodes each output for the whole
block, where the parameters allow it (:func:`block_form_missing`) and the block form reads
the block exactly; else it runs the node's pipeline message by message. Either way the
bytes, counters and state are the per-message form's.
"""
from __future__ import annotations

import contextlib
import gc
import itertools
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, TYPE_CHECKING

from rotation_node import pipeline, registry
from rotation_node.bag.block_codec import block_encoder, InputBlockDecoder, OutputBlockEncoder
from rotation_node.pipeline import BLOCK_SAMPLES, ConversionPipeline
from rotation_node.wire.cdr import fixed_layout_codec

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

BLOCK_MESSAGES = BLOCK_SAMPLES   # messages read per block (of all topics together)
DEFERRED_COLLECTION_THRESHOLD = 50_000   # allocations between youngest-generation passes

Output = Tuple[str, str, bytes]   # (output topic, type name, CDR data) of one output message


@contextlib.contextmanager
def collections_deferred() -> Iterator[None]:
    """
    Run the block with the cyclic garbage collector's passes made rarer; restore them after.

    The default pass every 700 allocations found nothing in a bag's short-lived objects and
    cost a sixth of the conversion time (``bench_bag_convert.py``).
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

    The one place that decides it: the pipeline's block form (input type, frames, values,
    outputs), a fixed CDR layout of the input type, a block encoder for every output.
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

    ``outputs`` is ``{output name: (output topic, type name, encode(header, numbers))}`` for
    every name in ``params.outputs``; ``blocks=False`` converts message by message (the
    reference the block form is checked against). ``pipeline.stats`` count every message,
    whichever way it went; ``block_form_missing`` says why not in blocks (None: in blocks).
    """

    def __init__(self, params: NodeParameters, outputs: Dict[str, tuple], *, blocks: bool = True):
        self.pipeline = ConversionPipeline(params)
        self._outputs = [(name, *outputs[name]) for name in params.outputs]
        self._by_name = {name: output for name, *output in self._outputs}
        input_type = registry.INPUTS[params.input_type]
        codec = fixed_layout_codec(input_type.type_name)
        self._decode = None if codec is None else codec.decode
        self.block_form_missing = block_form_missing(params) if blocks else 'blocks disabled'
        if self.block_form_missing is None:
            self._decoder = InputBlockDecoder(input_type, self.pipeline.reads_angular_velocity)
            self._encoders = [OutputBlockEncoder(registry.OUTPUTS[name].message)
                              for name in params.outputs]

    def convert(self, records: List, input_topics: Optional[List[str]] = None
                ) -> List[List[Output]]:
        """
        Return the outputs of each record (a :class:`~rotation_node.bag.records.BagMessage`).

        ``input_topics`` names the input type's topic each came on (default ``input``).
        BagError, where the per-message conversion raises it, for an invalid message.
        """
        block = self._converted_block(records)
        if block is not None:
            headers, converted = block
            result: List[List[Output]] = [[] for _ in records]
            for (name, topic, type_name, _), encoder in zip(self._outputs, self._encoders):
                present = converted.present[name]
                datas = encoder.encode(headers, present, converted.numbers[name])
                for index, data in zip(present.nonzero()[0].tolist(), datas):
                    result[index].append((topic, type_name, data))
            return result
        result = []
        for values in self._message_values(records, input_topics):
            encoded = []
            for name, header, numbers in values:
                topic, type_name, encode = self._by_name[name]
                encoded.append((topic, type_name, encode(header, numbers)))
            result.append(encoded)
        return result

    def convert_values(self, records: List, input_topics: Optional[List[str]] = None
                       ) -> List[List[Tuple[str, Any, Any]]]:
        """
        Return :meth:`convert`'s outputs before encoding: ``[(output name, header, numbers)]``.

        Outputs of one sample share its ``header`` object (a read-only view).
        """
        block = self._converted_block(records)
        if block is None:
            return self._message_values(records, input_topics)
        converted = block[1]
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

    def _converted_block(self, records):
        """Return the block form's ``(decoded block, outputs)``, or None where it declines."""
        if self.block_form_missing is not None or len(records) < 2:   # a plain type: one topic
            return None
        decoded = self._decoder.decode([record.data for record in records])
        if decoded is None:
            return None
        converted = self.pipeline.process_block(decoded[0])
        return None if converted is None else (decoded[1], converted)

    def _message_values(self, records, input_topics):
        """Return the pipeline's values of each record, message by message."""
        if input_topics is None:
            input_topics = [registry.INPUT_TOPIC.name] * len(records)
        return [self.pipeline.process_values(record.message(self._decode), topic)
                for record, topic in zip(records, input_topics)]


def converted_blocks(records: Iterable, converters: Dict[str, TopicConverter],
                     routes: Optional[Dict[str, Tuple[str, str]]] = None
                     ) -> Iterator[List[Tuple[Any, Optional[List[Output]]]]]:
    """
    Give the records in blocks of at most :data:`BLOCK_MESSAGES`, each with its outputs.

    ``routes``: ``{bag topic: (stream, the input type's topic name)}``, by default each
    ``converters`` key a plain type's bag topic; other records get None.
    """
    if routes is None:
        routes = {topic: (topic, registry.INPUT_TOPIC.name) for topic in converters}
    for block in message_blocks(records):
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


def message_blocks(records: Iterable) -> Iterator[List[Any]]:
    """Give the records in lists of :data:`BLOCK_MESSAGES`, the last one shorter."""
    records = iter(records)
    while block := list(itertools.islice(records, BLOCK_MESSAGES)):
        yield block
