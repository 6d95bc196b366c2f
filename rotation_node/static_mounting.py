"""
The mounting rotation read once from ``/tf_static`` between two named frames.

With ``mounting.tf_sensor_frame`` and ``mounting.tf_body_frame`` set, the
body-side rotation ``M`` of ``R' = W R M`` (:mod:`rotation_node.mounting`) is
the orientation of ``tf_body_frame`` in ``tf_sensor_frame`` as the static
transforms give it: tf2's
``lookupTransform(tf_sensor_frame, tf_body_frame)``, composed along the tree
(e.g. ``imu_link`` -> ``base_link`` through the robot's URDF). It is looked up
once: the live node until the transforms connect the two frames (its input is
dropped until then, counted as ``mounting_unknown``), ``rotation_bag
convert`` and ``export`` from the bag's ``/tf_static`` before converting. The
parameters are then :func:`resolved`: ``mounting.body_rotation`` holds the
quaternion found and the two frames are cleared, so every pipeline sees a
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
    """
    Tell whether the parameters ask for the mounting from ``/tf_static``.

    Raises
    ------
    ParameterError
        Only one of the two frames is set.

    """
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
    """
    Static transforms in, the mounting out once the two frames connect.

    Parameters
    ----------
    params : NodeParameters
        With ``mounting.tf_sensor_frame`` and ``mounting.tf_body_frame`` set.

    """

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
        """
        Add the transforms of one ``tf2_msgs/TFMessage`` of ``/tf_static``.

        Returns
        -------
        NodeParameters or None
            The :func:`resolved` parameters once the frames connect; None
            before (``problem`` says why).

        """
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
    Return the parameters with the mounting read from the bag's ``/tf_static``, if they ask.

    Parameters
    ----------
    reader : rotation_node.bag.reading.reader.InputBag
        The open bag.
    params : NodeParameters
        The node's parameters; returned as they are unless they name the frames.

    Raises
    ------
    BagError
        The bag has no ``/tf_static`` or its static transforms do not connect
        the two frames; the message names them.

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
