"""
CDR of many messages at once: a block of input messages into arrays, output numbers into bytes.

The block form of :mod:`rotation_node.wire.cdr` for ``rotation_bag convert``:
:class:`InputBlockDecoder` reads the samples of a block of messages of a
plain input type into a :class:`rotation_node.block_pipeline.SampleBlock`
(each field gathered for the whole block with numpy from the joined bytes:
a fixed-layout type is at fixed offsets once the lengths of its strings are
known), and :class:`OutputBlockEncoder` writes the numbers of a block of
output messages under their input messages' headers.

The bytes are those of the per-message path (``FixedLayoutCodec.decode``,
the pipeline, ``OutputMessage.encoder``) exactly. Where that path would do
something the block form does not (data that is not little-endian CDR, a
truncated message, a ``frame_id`` that is not NUL-terminated UTF-8, which
the per-message path rewrites), :meth:`InputBlockDecoder.decode` returns
None and the caller converts that block message by message.
"""
from __future__ import annotations

from typing import List, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from rotation_node import messages
from rotation_node.sample_block import SampleBlock
from rotation_node.wire.cdr import CDR_LE, fixed_layout_codec

_HEADER_PATHS = ['header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id']
_HEADER_FIXED = 12   # stamp (8 bytes) and the frame_id's uint32 length, before its bytes
_NS_PER_S = 1_000_000_000


def _gathered(buffer, positions, width):
    """Return the ``width`` bytes at each of ``positions`` in ``buffer``: (n, width) uint8."""
    return buffer[positions[:, None] + np.arange(width)]


def _float64s(buffer, positions, count):
    """Return the ``count`` little-endian float64 at each position: an (n, count) array."""
    return _gathered(buffer, positions, 8 * count).view('<f8')


class BlockHeaders(NamedTuple):
    """
    The headers of a decoded block, grouped by the length of their payload bytes.

    Attributes
    ----------
    group : ndarray of int, shape (n,)
        Each message's group.
    payloads : list of ndarray
        Per group, the header's payload bytes of its messages ``(count, length)``
        in message order: stamp, frame_id length and frame_id with its NUL.

    """

    group: np.ndarray
    payloads: List[np.ndarray]


class InputBlockDecoder:
    """
    Decode blocks of CDR messages of a plain input type into sample arrays.

    Parameters
    ----------
    input_type : rotation_node.messages.InputType
    angular_velocity : bool
        Read the angular velocity (and its unknown flag) too.

    Raises
    ------
    ValueError
        If the type has no fixed layout or does not start with a std_msgs/Header.

    """

    def __init__(self, input_type: messages.InputType, angular_velocity: bool):
        codec = fixed_layout_codec(input_type.type_name)
        if codec is None:
            raise ValueError(f'input_type: {input_type.type_name} has no fixed CDR layout')
        if [leaf.path for leaf in codec.leaves[:3]] != _HEADER_PATHS:
            raise ValueError(f'input_type: {input_type.type_name} does not start with a header')
        self._codec = codec
        self._input_type = input_type
        components = ('x', 'y', 'z', 'w') if (
            input_type.orientation_form == messages.QUATERNION) else ('x', 'y', 'z')
        self._orientation = [f'{input_type.orientation_field}.{c}' for c in components]
        # Paths of the angular velocity read: none when it is not read.
        self._rate: List[str] = (
            [] if not angular_velocity or input_type.angular_velocity_field is None
            else [f'{input_type.angular_velocity_field}.{c}' for c in 'xyz'])
        self._orientation_unknown = input_type.orientation_unknown_field
        self._rate_unknown = input_type.angular_velocity_unknown_field if self._rate else None

    def decode(self, datas: Sequence[bytes]) -> Optional[Tuple[SampleBlock, BlockHeaders]]:
        """
        Decode a block of messages.

        Parameters
        ----------
        datas : sequence of bytes
            The CDR data of each message (with the encapsulation header).

        Returns
        -------
        (SampleBlock, BlockHeaders) or None
            None if a message is not one the block form reads exactly as the
            per-message decoder does (then decode the block message by message).

        """
        n = len(datas)
        lengths = np.fromiter(map(len, datas), dtype=np.int64, count=n)
        if n == 0 or lengths.min() < 4 + _HEADER_FIXED:
            return None
        buffer = np.frombuffer(b''.join(datas), dtype=np.uint8)
        starts = np.cumsum(lengths) - lengths
        if not ((buffer[starts] == CDR_LE[0]) & (buffer[starts + 1] == CDR_LE[1])).all():
            return None
        sizes = lengths - 4
        payload = starts + 4
        string_lengths = []
        offset = np.zeros(n, dtype=np.int64)
        for to_length in self._codec.to_string_lengths:
            offset += np.asarray(to_length)[offset & 7]
            if (offset > sizes).any():
                return None
            length = _gathered(buffer, payload + offset - 4, 4).view('<u4')[:, 0].astype(np.int64)
            offset += length
            if (offset > sizes).any():
                return None
            string_lengths.append(length)
        keys = np.stack(string_lengths, axis=1)
        unique, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.reshape(-1)
        orientation = np.empty((n, len(self._orientation)))
        orientation_known = np.ones(n, dtype=bool)
        stamp_ns = np.empty(n, dtype=np.int64)
        rate = np.empty((n, len(self._rate)))
        rate_known = np.ones(n, dtype=bool)
        headers = []
        for g, key in enumerate(unique.tolist()):
            members = np.flatnonzero(group == g)
            offsets = self._codec.leaf_offsets(tuple(key))
            if (self._codec.payload_size(tuple(key)) > sizes[members]).any():
                return None
            base = payload[members]
            frame_length = key[0]
            header_length = _HEADER_FIXED + frame_length
            header = _gathered(buffer, base, header_length)
            if not _canonical_strings(header[:, _HEADER_FIXED:]):
                return None
            headers.append(header)
            seconds = header[:, :4].copy().view('<i4')[:, 0].astype(np.int64)
            nanoseconds = header[:, 4:8].copy().view('<u4')[:, 0].astype(np.int64)
            stamp_ns[members] = seconds * _NS_PER_S + nanoseconds
            for column, path in enumerate(self._orientation):
                orientation[members, column] = _float64s(buffer, base + offsets[path], 1)[:, 0]
            if self._orientation_unknown is not None:
                flag = _float64s(buffer, base + offsets[self._orientation_unknown], 1)[:, 0]
                orientation_known[members] = flag != -1.0
            for column, path in enumerate(self._rate):
                rate[members, column] = _float64s(buffer, base + offsets[path], 1)[:, 0]
            if self._rate_unknown is not None:
                flag = _float64s(buffer, base + offsets[self._rate_unknown], 1)[:, 0]
                rate_known[members] = flag != -1.0
        return (SampleBlock(stamp_ns, orientation, orientation_known,
                            rate if self._rate else None, rate_known if self._rate else None),
                BlockHeaders(group, headers))


def _canonical_strings(strings):
    """
    Whether every row (a frame_id's bytes with its NUL) reads back as the same bytes.

    The per-message decoder drops a final NUL and replaces bytes that are not
    UTF-8; the encoder writes the text and a NUL. Equal bytes need a final NUL
    and valid UTF-8 before it.
    """
    if strings.shape[1] == 0 or (strings[:, -1] != 0).any():
        return False
    text = strings[:, :-1]
    if not (text >= 0x80).any():
        return True
    for row in np.unique(text, axis=0):
        try:
            row.tobytes().decode('utf-8')
        except UnicodeDecodeError:
            return False
    return True


class OutputBlockEncoder:
    """
    Encode the numbers of a block of one output as CDR messages, as its per-message encoder does.

    Parameters
    ----------
    message : rotation_node.messages.OutputMessage

    Raises
    ------
    ValueError
        If the type has no block form (see :func:`block_encoder`).

    """

    def __init__(self, message: messages.OutputMessage):
        self.type_name = message.type_name
        self._prefix: Optional[bytes] = None   # the data's prefix of a Float64MultiArray
        self._width: int   # numbers per message
        if message.layout is not None:   # std_msgs/Float64MultiArray of a fixed size
            self._width = message.layout.dim[0].stride   # the outermost stride: every element
            encode = message.encoder()
            zero = encode(None, [0.0] * self._width)
            self._prefix = zero[:len(zero) - 8 * self._width]
            return
        codec = fixed_layout_codec(message.type_name) if message.stamped_numbers else None
        if codec is None or [leaf.path for leaf in codec.leaves[:3]] != _HEADER_PATHS or any(
                leaf.code != 'd' for leaf in codec.leaves[3:]):
            raise ValueError(f'message: {message.type_name} has no block encoding')
        self._width = sum(leaf.count or 1 for leaf in codec.leaves[3:])

    def encode(self, headers: BlockHeaders, present: np.ndarray, numbers: np.ndarray) -> list:
        """
        Return the CDR data of the messages of a block that have this output.

        Parameters
        ----------
        headers : BlockHeaders
            Of the whole block (as :meth:`InputBlockDecoder.decode` gave them).
        present : ndarray of bool, shape (n,)
            Which messages have the output.
        numbers : ndarray, shape (present.sum(), k)
            Their numbers, in message order.

        Returns
        -------
        list of bytes
            One per message that has the output, in message order.

        """
        count = int(np.count_nonzero(present))
        if count == 0:
            return []
        values = np.ascontiguousarray(numbers, dtype='<f8').reshape(count, self._width)
        if self._prefix is not None:
            return _rows(self._prefix, values.view(np.uint8))
        if len(headers.payloads) == 1:
            return self._stamped(headers.payloads[0][present], values)
        result = [None] * len(present)
        group = headers.group
        rows = np.cumsum(present) - 1
        for g, payload in enumerate(headers.payloads):
            members = group == g
            selected = present[members]
            which = np.flatnonzero(present & members)
            encoded = self._stamped(payload[selected], values[rows[which]])
            for index, data in zip(which.tolist(), encoded):
                result[index] = data
        return [data for data in result if data is not None]

    def _stamped(self, header, values):
        """Header payloads and numbers of messages of one header length into CDR."""
        length = header.shape[1]
        padding = -length % 8
        out = np.zeros((len(header), 4 + length + padding + 8 * self._width), dtype=np.uint8)
        out[:, :4] = np.frombuffer(CDR_LE, dtype=np.uint8)
        out[:, 4:4 + length] = header
        out[:, 4 + length + padding:] = values.view(np.uint8)
        return _rows(b'', out)


def _rows(prefix, rows):
    """Each row of a uint8 array as bytes, after ``prefix``."""
    width = rows.shape[1]
    if prefix:
        out = np.empty((len(rows), len(prefix) + width), dtype=np.uint8)
        out[:, :len(prefix)] = np.frombuffer(prefix, dtype=np.uint8)
        out[:, len(prefix):] = rows
        rows, width = out, out.shape[1]
    blob = rows.tobytes()
    return [blob[start:start + width] for start in range(0, len(blob), width)]


def block_encoder(message: messages.OutputMessage) -> Optional[OutputBlockEncoder]:
    """Return the block encoder of an output message type, or None if it has none."""
    try:
        return OutputBlockEncoder(message)
    except ValueError:
        return None
