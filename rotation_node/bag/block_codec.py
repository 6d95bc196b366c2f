"""
The conversion's blocks through the CDR codec: messages into samples, numbers into messages.

:class:`InputBlockDecoder` reads a block of a plain input type into a ``SampleBlock``,
:class:`OutputBlockEncoder` writes a block of one output's numbers under the input's
headers; the layouts and CDR rules are the codec's alone, so the bytes are the per-message
path's. A block the codec declines the caller converts message by message.
"""
from __future__ import annotations

from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np
from rotation_node import registry
from rotation_node.sample_block import SampleBlock
from rotation_node.wire.cdr import (
    DecodedBlock, fixed_layout_codec, FixedLayoutCodec, float64_multi_array_block_encoder,
    HEADER_PATHS)

_NS_PER_S = 1_000_000_000


class InputBlockDecoder:
    """
    Decode blocks of CDR messages of a plain input type into sample arrays.

    ``angular_velocity``: read it (and its unknown flag) too. ValueError if the type has no
    fixed layout or does not start with a std_msgs/Header.
    """

    def __init__(self, input_type: registry.InputType, angular_velocity: bool):
        codec = fixed_layout_codec(input_type.type_name)
        if codec is None:
            raise ValueError(f'input_type: {input_type.type_name} has no fixed CDR layout')
        if not codec.starts_with_header:
            raise ValueError(f'input_type: {input_type.type_name} does not start with a header')
        self._codec = codec
        components = ('x', 'y', 'z', 'w') if (
            input_type.orientation_form == registry.QUATERNION) else ('x', 'y', 'z')
        self._orientation = [f'{input_type.orientation_field}.{c}' for c in components]
        # Paths of the angular velocity read: none when it is not read.
        self._rate: List[str] = (
            [] if not angular_velocity or input_type.angular_velocity_field is None
            else [f'{input_type.angular_velocity_field}.{c}' for c in 'xyz'])
        self._orientation_unknown = input_type.orientation_unknown_field
        self._rate_unknown = input_type.angular_velocity_unknown_field if self._rate else None

    def decode(self, datas: Sequence[bytes]) -> Optional[Tuple[SampleBlock, DecodedBlock]]:
        """
        Return the samples of CDR messages and every field (the headers for the encoder).

        None if a message is not one the block form reads exactly as the per-message
        decoder does (then decode the block message by message).
        """
        decoded = self._codec.decode_block(datas)
        if decoded is None:
            return None
        n = len(datas)
        orientation = np.empty((n, len(self._orientation)))
        orientation_known = np.ones(n, dtype=bool)
        stamp_ns = np.empty(n, dtype=np.int64)
        rate = np.empty((n, len(self._rate)))
        rate_known = np.ones(n, dtype=bool)
        for g, fields in enumerate(decoded.records):
            members: Any = slice(None) if len(decoded.records) == 1 else decoded.group == g
            stamp_ns[members] = (fields['header.stamp.sec'].astype(np.int64) * _NS_PER_S
                                 + fields['header.stamp.nanosec'])
            for column, path in enumerate(self._orientation):
                orientation[members, column] = fields[path]
            for column, path in enumerate(self._rate):
                rate[members, column] = fields[path]
            # The first element of the flag's field (a covariance) -1: unknown.
            for known, flag in ((orientation_known, self._orientation_unknown),
                                (rate_known, self._rate_unknown)):
                if flag is not None:
                    known[members] = fields[flag].reshape(len(fields), -1)[:, 0] != -1.0
        return (SampleBlock(stamp_ns, orientation, orientation_known,
                            rate if self._rate else None, rate_known if self._rate else None),
                decoded)


class OutputBlockEncoder:
    """Encode a block of one output's numbers as its per-message encoder does (or ValueError)."""

    _codec: FixedLayoutCodec   # of a stamped type

    def __init__(self, message: registry.OutputMessage):
        self._encode_rows: Optional[Callable[[np.ndarray], List[bytes]]] = None
        if message.layout is not None:   # std_msgs/Float64MultiArray of a fixed size
            self._width = message.layout.dim[0].stride   # the outermost stride: every element
            self._encode_rows = float64_multi_array_block_encoder(message.layout, self._width)
            return
        codec = fixed_layout_codec(message.type_name) if message.stamped_numbers else None
        if codec is None or not codec.starts_with_header or any(
                leaf.code != 'd' for leaf in codec.leaves[len(HEADER_PATHS):]):
            raise ValueError(f'message: {message.type_name} has no block encoding')
        self._codec = codec
        # (path, the numbers' columns) of each field after the header.
        self._numbers: List[Tuple[str, Any]] = []
        self._width = 0   # numbers per message
        for leaf in codec.leaves[len(HEADER_PATHS):]:
            columns = (slice(self._width, self._width + leaf.count) if leaf.count
                       else self._width)
            self._numbers.append((leaf.path, columns))
            self._width += leaf.count or 1

    def encode(self, decoded: DecodedBlock, present: np.ndarray, numbers: np.ndarray) -> list:
        """
        Return the CDR data of the messages of a block that have this output, in order.

        ``decoded`` is the whole input block (its headers are the outputs'), ``present`` (n,)
        which messages have the output, ``numbers`` (present.sum(), k) theirs.
        """
        count = int(np.count_nonzero(present))
        if count == 0:
            return []
        values = np.asarray(numbers, dtype=np.float64).reshape(count, self._width)
        if self._encode_rows is not None:
            return self._encode_rows(values)
        if len(decoded.records) == 1:
            return self._stamped(decoded.records[0], present, values)
        result = [None] * len(present)
        rows = np.cumsum(present) - 1
        for g, records in enumerate(decoded.records):
            members = decoded.group == g
            which = np.flatnonzero(present & members)
            encoded = self._stamped(records, present[members], values[rows[which]])
            for index, data in zip(which.tolist(), encoded):
                result[index] = data
        return [data for data in result if data is not None]

    def _stamped(self, records, selected, values):
        """Encode the selected messages of one ``frame_id`` length: headers and ``values``."""
        layout = self._codec.layout(records.dtype['header.frame_id'].shape)
        every = selected.all()
        fields = {path: records[path] if every else records[path][selected]
                  for path in HEADER_PATHS}
        for path, columns in self._numbers:
            fields[path] = values[:, columns]
        return layout.encode_block(len(values), fields)


def block_encoder(message: registry.OutputMessage) -> Optional[OutputBlockEncoder]:
    """Return the block encoder of an output message type, or None if it has none."""
    try:
        return OutputBlockEncoder(message)
    except ValueError:
        return None
