"""
The ``tf`` input type: the orientation of one frame in another, from ``/tf`` and ``/tf_static``.

:class:`TfSampleStream` feeds every transform of each ``tf2_msgs/TFMessage``
into a :class:`~rotation_node.tf_buffer.TfOrientationBuffer` (those of
``/tf_static`` as static edges) and then looks up the orientation of
``tf.child_frame`` in ``tf.parent_frame`` at "latest" time, as tf2's
``lookupTransform(parent, child, Time(0))`` does. It gives one sample when the
lookup time has advanced past the previous sample's (for a chain of static
edges only, whose time is always 0: when it is first complete and whenever its
rotation changes), with a header whose ``frame_id`` is the parent frame and
whose stamp is the lookup time; otherwise none. A failed lookup, and each
transform tf2 would ignore, is reported with its reason and gives nothing.

The registry entry (:data:`rotation_node.registry.INPUTS` ``['tf']``) names
this module: :func:`sample_stream` and :data:`DROP_REASONS`. This module
does not import rclpy: the header class is looked up when a stream is created.
"""
from typing import Any, Callable, Optional, Tuple

import numpy as np
from rotation_node.registry import Sample, TF_STATIC_TOPIC
from rotation_node.tf_buffer import (
    CycleError, ExtrapolationError, NotConnectedError, TfLookupError, TfOrientation,
    TfOrientationBuffer, UnknownFrameError)
from rotation_node.wire.stamps import split_ns

TF_UNKNOWN_FRAME = 'tf_unknown_frame'
TF_NOT_CONNECTED = 'tf_not_connected'
TF_CYCLE = 'tf_cycle'
TF_EXTRAPOLATION = 'tf_extrapolation'
TF_SAMPLE_IGNORED = 'tf_sample_ignored'
DROP_REASONS = (TF_UNKNOWN_FRAME, TF_NOT_CONNECTED, TF_CYCLE, TF_EXTRAPOLATION,
                TF_SAMPLE_IGNORED)
"""Why a TF message gave no sample (a failed lookup), or a transform was ignored."""

_LOOKUP_REASONS = {
    UnknownFrameError: TF_UNKNOWN_FRAME,
    NotConnectedError: TF_NOT_CONNECTED,
    CycleError: TF_CYCLE,
    ExtrapolationError: TF_EXTRAPOLATION,
}


def sample_stream(params: Any, report: Callable[[str, str], None]) -> 'TfSampleStream':
    """Return the sample stream of one ``tf`` input (the registry's ``stream`` contract)."""
    return TfSampleStream(params, report)


class TfSampleStream:
    """
    Orientation samples of ``tf.child_frame`` in ``tf.parent_frame`` from TF messages.

    Parameters
    ----------
    params : rotation_node.parameters.NodeParameters
        ``tf_parent_frame`` and ``tf_child_frame`` name the frames.
    report : callable
        ``report(reason, detail)`` for each failed lookup (``tf_unknown_frame``,
        ``tf_not_connected``, ``tf_cycle``, ``tf_extrapolation``) and each
        ignored transform (``tf_sample_ignored``).

    """

    def __init__(self, params: Any, report: Callable[[str, str], None]):
        from rotation_node.wire.message_types import message_class
        self.parent, self.child = params.tf_parent_frame, params.tf_child_frame
        self.buffer = TfOrientationBuffer()
        self._report = report
        self._static_topic = TF_STATIC_TOPIC.name
        self._sample = Sample
        self._header_class = message_class('std_msgs/msg/Header')
        self._previous: Optional[TfOrientation] = None   # that of the previous sample

    def __call__(self, topic: str, msg: Any) -> Tuple[Any, ...]:
        """
        Add the transforms of one TFMessage; return the new sample, if any.

        Parameters
        ----------
        topic : str
            ``'/tf_static'`` for static transforms, ``'/tf'`` for dynamic ones
            (the input type's topic names, before any remapping).
        msg : tf2_msgs/msg/TFMessage or any object with its fields
            The transforms to add.

        Returns
        -------
        tuple of rotation_node.registry.Sample
            One sample (quaternion ``(x, y, z, w)``; header with the parent frame
            and the lookup time), or none.

        """
        buffer = self.buffer
        for exc in buffer.insert_transforms(msg.transforms, static=topic == self._static_topic):
            self._report(TF_SAMPLE_IGNORED, f'{exc} [{exc.reason}]')
        try:
            found = buffer.lookup_orientation(self.parent, self.child)
        except TfLookupError as exc:
            self._report(_LOOKUP_REASONS[type(exc)], f'no orientation of {self.child!r} in '
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
        return (self._sample(header, tuple(found.quaternion.tolist())),)
