"""
The ``tf`` input type: the orientation of one frame in another, from ``/tf`` and ``/tf_static``.

:class:`TfSampleStream` feeds each ``tf2_msgs/TFMessage`` into a
:class:`~rotation_node.tf_buffer.TfOrientationBuffer` and looks up ``tf.child_frame`` in
``tf.parent_frame`` at "latest" time. It gives a sample (header: the parent frame, the lookup
time) when that time advances past the previous sample's, or, for a static-only chain (time 0),
when it is first complete and whenever its rotation changes. Failed lookups and ignored
transforms are reported with their reason (:data:`DROP_REASONS`). No rclpy import.
"""
from typing import Any, Callable, Optional, Tuple

import numpy as np
from rotation_node.registry import Sample, TF_STATIC_TOPIC
from rotation_node.tf_buffer import (
    CycleError, ExtrapolationError, NotConnectedError, TfLookupError, TfOrientation,
    TfOrientationBuffer, UnknownFrameError)
from rotation_node.wire.stamps import split_ns

TF_SAMPLE_IGNORED = 'tf_sample_ignored'


def _lookup_reason(error: type[TfLookupError]) -> str:
    """Return the drop reason of a failed lookup: ``tf_`` and the error's ``reason``."""
    return 'tf_' + error.reason


#: Why a TF message gave no sample (tf_unknown_frame, tf_not_connected, tf_cycle,
#: tf_extrapolation: :func:`_lookup_reason` of each lookup error), or a transform was ignored.
DROP_REASONS = tuple(_lookup_reason(error) for error in (
    UnknownFrameError, NotConnectedError, CycleError, ExtrapolationError)) + (TF_SAMPLE_IGNORED,)


def sample_stream(params: Any, report: Callable[[str, str], None]) -> 'TfSampleStream':
    """Return the sample stream of one ``tf`` input (the registry's ``stream`` contract)."""
    return TfSampleStream(params, report)


class TfSampleStream:
    """Orientation samples of ``params.tf_child_frame`` in ``params.tf_parent_frame``."""

    def __init__(self, params: Any, report: Callable[[str, str], None]):
        from rotation_node.wire.message_types import message_class
        self.parent, self.child = params.tf_parent_frame, params.tf_child_frame
        self.buffer = TfOrientationBuffer()
        self._report = report
        self._header_class = message_class('std_msgs/msg/Header')
        self._previous: Optional[TfOrientation] = None   # that of the previous sample

    def __call__(self, topic: str, msg: Any) -> Tuple[Any, ...]:
        """Add a TFMessage of ``topic`` (named before remapping); return the new sample, if any."""
        buffer = self.buffer
        for exc in buffer.insert_transforms(msg.transforms,
                                            static=topic == TF_STATIC_TOPIC.name):
            self._report(TF_SAMPLE_IGNORED, f'{exc} [{exc.reason}]')
        try:
            found = buffer.lookup_orientation(self.parent, self.child)
        except TfLookupError as exc:
            self._report(_lookup_reason(type(exc)), f'no orientation of {self.child!r} in '
                         f'{self.parent!r}: {exc}')
            return ()
        previous = self._previous
        if previous is not None and not (
                found.stamp_ns > previous.stamp_ns
                or (found.stamp_ns == previous.stamp_ns == 0
                    and not np.array_equal(found.quaternion, previous.quaternion))):
            return ()
        self._previous = found
        header = self._header_class(frame_id=self.parent)
        header.stamp.sec, header.stamp.nanosec = split_ns(found.stamp_ns)
        return (Sample(header, tuple(found.quaternion.tolist())),)
