"""
The mounting rotation read once from ``/tf_static`` between two named frames.

With ``mounting.tf_sensor_frame`` and ``mounting.tf_body_frame`` set, ``M`` of ``R' = W R M``
is tf2's ``lookupTransform(tf_sensor_frame, tf_body_frame)`` over the static transforms,
looked up once (the node: when the frames connect, dropping input until then; ``convert`` and
``export``: from the bag before converting). The parameters are then :func:`resolved`: the
quaternion found in ``mounting.body_rotation``, the frames cleared, so every pipeline sees a
plain mounting.
"""
from __future__ import annotations

from typing import Any, Optional, TYPE_CHECKING

from rotation_node.errors import BagError, ParameterError
from rotation_node.parameters import mounting_frames_problem
from rotation_node.registry import TF_STATIC_TOPIC as _TF_STATIC_INPUT
from rotation_node.tf_buffer import TfLookupError, TfOrientationBuffer

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

#: Why the node drops input until the mounting is known (counted in ``dropped``).
MOUNTING_UNKNOWN = 'mounting_unknown'

#: The topic of static transforms (the ``tf`` input type's ``/tf_static``).
TF_STATIC_TOPIC = _TF_STATIC_INPUT.name


def needs_static_mounting(params: NodeParameters) -> bool:
    """Tell whether the parameters ask for the mounting from ``/tf_static`` (one frame: error)."""
    problem = mounting_frames_problem(params)
    if problem:
        raise ParameterError(problem)
    return bool(params.mounting_tf_sensor_frame)


def resolved(params: NodeParameters, quaternion: Any) -> NodeParameters:
    """Return the parameters with ``mounting.body_rotation`` = ``quaternion``, frames cleared."""
    return params.replaced({'mounting.body_rotation': [float(c) for c in quaternion],
                            'mounting.tf_sensor_frame': '', 'mounting.tf_body_frame': ''})


def placeholder(params: NodeParameters) -> NodeParameters:
    """Return the parameters with the frames cleared (identity ``M``) until the lookup succeeds."""
    return params.replaced({'mounting.tf_sensor_frame': '', 'mounting.tf_body_frame': ''})


class StaticMountingLookup:
    """Static transforms in, the :func:`resolved` parameters out once the two frames connect."""

    def __init__(self, params: NodeParameters) -> None:
        self.params = params
        self.sensor, self.body = params.mounting_tf_sensor_frame, params.mounting_tf_body_frame
        self.buffer = TfOrientationBuffer()
        self.problem = 'no /tf_static transform received yet'

    @property
    def frames(self) -> str:
        """Return ``'<body> in <sensor>'`` for messages."""
        return f'{self.body!r} in {self.sensor!r}'

    def add(self, msg: Any) -> Optional[NodeParameters]:
        """Add a ``/tf_static`` TFMessage; return the resolved parameters or None (``problem``)."""
        for exc in self.buffer.insert_transforms(msg.transforms, static=True):
            self.problem = str(exc)
        try:
            found = self.buffer.lookup_orientation(self.sensor, self.body)
        except TfLookupError as exc:
            self.problem = str(exc)
            return None
        return resolved(self.params, found.quaternion)


def resolved_from_bag(reader: Any, params: NodeParameters) -> NodeParameters:
    """
    Return the parameters with the mounting read from an open bag's ``/tf_static``, if they ask.

    BagError naming the frames if the bag has no ``/tf_static`` or it does not connect them.
    """
    if not needs_static_mounting(params):
        return params
    lookup = StaticMountingLookup(params)
    if TF_STATIC_TOPIC not in reader.topics:
        raise BagError(f'{reader.path}: mounting.tf_sensor_frame and mounting.tf_body_frame '
                       f'ask for {lookup.frames} from /tf_static, and the bag has no /tf_static')
    for record in reader.messages([TF_STATIC_TOPIC]):
        found = lookup.add(record.message())
        if found is not None:
            return found
    raise BagError(f"{reader.path}: the bag's /tf_static gives no orientation of "
                   f'{lookup.frames} (mounting.tf_body_frame, mounting.tf_sensor_frame): '
                   f'{lookup.problem}')
