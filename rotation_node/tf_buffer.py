"""
Orientations from a TF tree, with the semantics of tf2's ``BufferCore``.

:class:`TfOrientationBuffer` keeps the edges of a TF tree (parent -> child,
from ``geometry_msgs/TransformStamped`` samples of ``/tf`` and ``/tf_static``)
and answers :meth:`~TfOrientationBuffer.lookup_orientation`: the orientation of
one frame in another, composed along the tree between them (up from the child
to the common ancestor, down to the parent), whatever the number of edges.

It is a port of tf2's lookup (``BufferCore::lookupTransform``,
``walkToTopParent``, ``getLatestCommonTime`` and ``TimeCache``), restricted to
rotations: translations are checked as tf2 checks them (a transform tf2 would
ignore is ignored here too) but not stored, so the buffer answers
orientation lookups only. In particular:

- A lookup at time 0 (``Time(0)``, "latest") is done at the latest time at which
  every dynamic edge between the two frames is known, the minimum over those
  edges of their newest stamp; each dynamic edge is interpolated to that time
  (slerp between the two samples around it; a sample whose stamp equals the
  time is returned as it is), static edges are used as they are. A chain of
  static edges only has time 0. A dynamic edge's sample with stamp 0 does not
  take part in the minimum, as in tf2.
- A dynamic edge keeps ``cache_time_ns`` (10 s by default, tf2's) behind its
  newest sample: before each insertion, samples older than the newest stamp
  minus the cache time are dropped, and a sample older than that is rejected
  (``TF_OLD_DATA``). A duplicate sample (same stamp, rotation and parent) is
  kept once.
- A dynamic edge with one sample answers only at that sample's stamp; a time
  between two samples interpolates, outside them is an extrapolation error.
  tf2 does not extrapolate and neither does this buffer.
- A frame may change parent over time; a lookup follows the parent each edge
  had at the lookup time, as tf2 does. An edge that turns from dynamic to
  static (or back) starts afresh.

Errors are typed (:class:`TfLookupError` and its subclasses for lookups,
:class:`RejectedTransformError` for samples) and carry a ``reason`` for
counters and a message naming the frames. Quaternions are ``(x, y, z, w)``; a
sample's rotation is normalised when stored (tf2 accepts norms within 1% of one
and uses them as given; the rotation is the same). Times are integer
nanoseconds (as ``builtin_interfaces/Time`` ``sec * 10**9 + nanosec``).
"""
from bisect import bisect_right
import math
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Set, Tuple, Union

import numpy as np

from rotation_node import conversions
from rotation_node.errors import RotationNodeError
from rotation_node.kinematics import slerp
from rotation_node.wire.stamps import seconds_text, stamp_ns as _stamp_ns

DEFAULT_CACHE_TIME_NS = 10_000_000_000
"""How long a dynamic edge keeps its samples behind the newest one (tf2's default, 10 s)."""

MAX_GRAPH_DEPTH = 1000
"""Longest walk from a frame towards the root, in edges; tf2 calls a deeper one a loop."""

QUATERNION_NORM_TOLERANCE = 10e-3
"""tf2 ignores a sample whose squared quaternion norm differs from 1 by this much or more."""

_IDENTITY = np.array((0.0, 0.0, 0.0, 1.0))


class TfError(RotationNodeError):
    """
    A TF sample or lookup could not be used; ``reason`` names the kind, for counters.

    Attributes
    ----------
    reason : str
        Short identifier of the kind of error, e.g. ``'not_connected'``.

    """

    reason = 'tf_error'


class RejectedTransformError(TfError):
    """A sample was ignored, as tf2 ignores it (self transform, NaN, old data...)."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


class TfLookupError(TfError):
    """A lookup has no answer (base class of the lookup errors below)."""


class UnknownFrameError(TfLookupError):
    """A frame of the lookup appears in no sample (neither as a parent nor as a child)."""

    reason = 'unknown_frame'


class NotConnectedError(TfLookupError):
    """The two frames are in different trees: no chain of edges joins them."""

    reason = 'not_connected'


class CycleError(TfLookupError):
    """The walk towards the root loops (or exceeds :data:`MAX_GRAPH_DEPTH` edges, as in tf2)."""

    reason = 'cycle'


class ExtrapolationError(TfLookupError):
    """An edge has no data at the lookup time (tf2's extrapolation exceptions)."""

    reason = 'extrapolation'


class TfOrientation(NamedTuple):
    """
    The answer of a lookup.

    Attributes
    ----------
    stamp_ns : int
        The lookup time in nanoseconds: for a "latest" lookup the latest common
        time of the chain's dynamic edges, 0 for a chain of static edges only.
    quaternion : ndarray, shape (4,)
        Orientation of the child frame in the parent frame, (x, y, z, w), unit,
        canonical (w >= 0): it maps child coordinates to parent coordinates.

    """

    stamp_ns: int
    quaternion: np.ndarray


# ----------------------------------------------------------------------------- edges

class _Sample(NamedTuple):
    stamp_ns: int
    quaternion: np.ndarray
    parent: str


class _StaticEdge:
    """tf2's ``StaticCache``: one sample, valid at every time."""

    def __init__(self, sample: _Sample):
        self.sample = sample

    def insert(self, sample: _Sample, cache_time_ns: int) -> bool:
        self.sample = sample
        return True

    def latest(self) -> Tuple[int, str]:
        return 0, self.sample.parent

    def data(self, time_ns: int, child: str) -> _Sample:
        return self.sample


class _DynamicEdge:
    """tf2's ``TimeCache``: samples sorted by stamp (oldest first), slerp between them."""

    def __init__(self, sample: _Sample):
        self.samples = [sample]
        self._stamps: List[int] = [sample.stamp_ns]

    def insert(self, sample: _Sample, cache_time_ns: int) -> bool:
        newest = self._stamps[-1]
        # Prune first, against the newest stamp before this sample (as tf2 does).
        keep = bisect_right(self._stamps, newest - cache_time_ns - 1)
        del self.samples[:keep], self._stamps[:keep]
        if sample.stamp_ns < newest - cache_time_ns:
            return False
        position = bisect_right(self._stamps, sample.stamp_ns)
        for other in reversed(self.samples[:position]):
            if other.stamp_ns != sample.stamp_ns:
                break
            if other.parent == sample.parent and np.array_equal(other.quaternion,
                                                                sample.quaternion):
                return True   # a duplicate: kept once
        # After the samples of equal stamp: among those, the newest insertion counts as newest.
        self.samples.insert(position, sample)
        self._stamps.insert(position, sample.stamp_ns)
        return True

    def latest(self) -> Tuple[int, str]:
        newest = self.samples[-1]
        return newest.stamp_ns, newest.parent

    def data(self, time_ns: int, child: str) -> _Sample:
        """Return the sample at ``time_ns`` (0: the newest), interpolated, or raise."""
        samples, stamps = self.samples, self._stamps
        if time_ns == 0:
            return samples[-1]
        if len(samples) == 1:
            if stamps[0] == time_ns:
                return samples[0]
            raise ExtrapolationError(
                f'edge {samples[0].parent} -> {child}: lookup would require extrapolation '
                f'at time {seconds_text(time_ns)} s, but only time {seconds_text(stamps[0])} s '
                'is in the buffer')
        if time_ns == stamps[-1]:
            return samples[-1]
        if time_ns == stamps[0]:
            return samples[0]
        if time_ns > stamps[-1]:
            raise ExtrapolationError(
                f'edge {samples[-1].parent} -> {child}: lookup would require extrapolation '
                f'into the future: requested time {seconds_text(time_ns)} s but the latest '
                f'data is at time {seconds_text(stamps[-1])} s')
        if time_ns < stamps[0]:
            raise ExtrapolationError(
                f'edge {samples[0].parent} -> {child}: lookup would require extrapolation '
                f'into the past: requested time {seconds_text(time_ns)} s but the earliest '
                f'data is at time {seconds_text(stamps[0])} s')
        index = bisect_right(stamps, time_ns) - 1
        older, newer = samples[index], samples[index + 1]
        if older.parent != newer.parent or older.stamp_ns == time_ns:
            return older
        fraction = (time_ns - older.stamp_ns) / (newer.stamp_ns - older.stamp_ns)
        return _Sample(time_ns, slerp(older.quaternion, newer.quaternion, fraction),
                       older.parent)


# ---------------------------------------------------------------------------- buffer

class TfOrientationBuffer:
    """
    The rotations of a TF tree over time, looked up as tf2 looks up transforms.

    Parameters
    ----------
    cache_time_ns : int, optional
        How long each dynamic edge keeps samples behind its newest one, in
        nanoseconds (default 10 s, tf2's ``BUFFER_CORE_DEFAULT_CACHE_TIME``).

    Notes
    -----
    Translations are not stored: this buffer answers orientation lookups only.
    Frame names are used as tf2 uses them: a leading ``/`` of a sample's
    frame is dropped, and the names are otherwise compared exactly.

    """

    def __init__(self, cache_time_ns: int = DEFAULT_CACHE_TIME_NS):
        if not isinstance(cache_time_ns, int) or cache_time_ns < 0:
            raise ValueError(f'Expected `cache_time_ns` to be a non-negative int, '
                             f'got {cache_time_ns!r}.')
        self.cache_time_ns = cache_time_ns
        self._frames: Set[str] = set()   # every frame named by a sample, as parent or child
        # child -> the edge to its parent
        self._edges: Dict[str, Union[_StaticEdge, _DynamicEdge]] = {}

    def __contains__(self, frame: str) -> bool:
        """Whether ``frame`` appears in a sample (as a parent or a child)."""
        return frame in self._frames

    def insert(self, parent: str, child: str, stamp_ns: int, quaternion: Sequence[float], *,
               static: bool = False,
               translation: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """
        Add one sample of the edge ``parent -> child`` (one TransformStamped).

        Parameters
        ----------
        parent, child : str
            ``header.frame_id`` and ``child_frame_id``; a leading ``/`` is dropped.
        stamp_ns : int
            ``header.stamp`` in nanoseconds.
        quaternion : sequence of 4 float
            ``transform.rotation`` (x, y, z, w): the orientation of ``child`` in
            ``parent``; its squared norm must be within 1% of 1, as tf2 requires.
        static : bool, optional
            True for ``/tf_static`` (valid at every time, replaces the previous one).
        translation : sequence of 3 float, optional
            ``transform.translation``, only checked for NaN (as tf2 does); not stored.

        Raises
        ------
        RejectedTransformError
            tf2 would ignore this sample: ``reason`` is ``self_transform``,
            ``no_child_frame_id``, ``no_frame_id``, ``nan_input``,
            ``denormalized_quaternion`` or ``old_data``. The edge is unchanged
            (an old sample's frames are known from then on, as in tf2).

        """
        if not isinstance(stamp_ns, int):
            raise ValueError(f'Expected `stamp_ns` to be an int (nanoseconds), got {stamp_ns!r}.')
        parent, child = _stripped(parent), _stripped(child)
        x, y, z, w = (float(v) for v in quaternion)
        reasons = []
        if child == parent:
            reasons.append(('self_transform', f'frame_id and child_frame_id are both {child!r}'))
        if not child:
            reasons.append(('no_child_frame_id', 'child_frame_id is empty'))
        if not parent:
            reasons.append(('no_frame_id', 'frame_id is empty'))
        if any(map(math.isnan, (x, y, z, w, *(float(v) for v in translation)))):
            reasons.append(('nan_input', f'NaN in rotation ({x}, {y}, {z}, {w}) or '
                            f'translation {tuple(translation)}'))
        elif not abs(x * x + y * y + z * z + w * w - 1.0) < QUATERNION_NORM_TOLERANCE:
            reasons.append(('denormalized_quaternion',
                            f'rotation ({x}, {y}, {z}, {w}) is not a unit quaternion'))
        if reasons:
            raise RejectedTransformError(
                reasons[0][0],
                f'transform {parent!r} -> {child!r} ignored: '
                + '; '.join(detail for _, detail in reasons))
        sample = _Sample(stamp_ns, conversions.canonical_quaternion((x, y, z, w)), parent)
        self._frames.update((parent, child))   # as tf2: named even if the sample is too old
        edge = self._edges.get(child)
        if edge is None or isinstance(edge, _StaticEdge) != static:
            self._edges[child] = (_StaticEdge if static else _DynamicEdge)(sample)
        elif not edge.insert(sample, self.cache_time_ns):
            newest = edge.latest()[0]
            raise RejectedTransformError(
                'old_data',
                f'transform {parent!r} -> {child!r} ignored: stamp {seconds_text(stamp_ns)} s is '
                f'more than the cache time {seconds_text(self.cache_time_ns)} s before the '
                f'newest sample of that edge ({seconds_text(newest)} s)')

    def insert_transforms(self, transforms: Sequence[Any], *,
                          static: bool = False) -> List[RejectedTransformError]:
        """Add the ``TransformStamped`` of a TFMessage; return why tf2 would ignore any of them."""
        rejected = []
        for transform in transforms:
            header, rotation = transform.header, transform.transform.rotation
            translation = transform.transform.translation
            try:
                self.insert(header.frame_id, transform.child_frame_id, _stamp_ns(header.stamp),
                            (rotation.x, rotation.y, rotation.z, rotation.w), static=static,
                            translation=(translation.x, translation.y, translation.z))
            except RejectedTransformError as exc:
                rejected.append(exc)
        return rejected

    def lookup_orientation(self, parent: str, child: str, stamp_ns: int = 0) -> TfOrientation:
        """
        Orientation of ``child`` in ``parent``: tf2's ``lookupTransform(parent, child, time)``.

        Parameters
        ----------
        parent, child : str
            Target and source frame of tf2's lookup; different, not empty,
            without a leading ``/``.
        stamp_ns : int, optional
            Lookup time in nanoseconds; 0 (default) is tf2's ``Time(0)``: the
            latest time at which every dynamic edge between the frames is known.

        Returns
        -------
        TfOrientation
            The lookup time and the composed, interpolated rotation.

        Raises
        ------
        ValueError
            ``parent`` or ``child`` empty, starting with ``/``, or equal.
        UnknownFrameError
            A frame appears in no sample.
        NotConnectedError
            No chain of edges joins the frames.
        CycleError
            The tree between them loops.
        ExtrapolationError
            A dynamic edge of the chain has no data at the lookup time.

        """
        for name, value in (('parent', parent), ('child', child)):
            if not isinstance(value, str) or not value or value.startswith('/'):
                raise ValueError(f'Expected `{name}` to be a frame name (not empty, no '
                                 f'leading /), got {value!r}.')
        if parent == child:
            raise ValueError(f'Expected `parent` and `child` to be different frames, '
                             f'got {parent!r} twice.')
        if not isinstance(stamp_ns, int) or stamp_ns < 0:
            raise ValueError(f'Expected `stamp_ns` to be a non-negative int, got {stamp_ns!r}.')
        unknown = [f'{frame!r} ({role})' for frame, role in ((parent, 'parent'), (child, 'child'))
                   if frame not in self._frames]
        if unknown:
            subject = ('frame {} does not exist (no transform names it)' if len(unknown) == 1
                       else 'frames {} do not exist (no transform names them)')
            raise UnknownFrameError(
                f'{subject.format(" and ".join(unknown))}, looking up {child!r} in {parent!r}')
        if stamp_ns == 0:
            stamp_ns = self._latest_common_time(parent, child)
        quaternion = self._walk(parent, child, stamp_ns)
        return TfOrientation(stamp_ns, conversions.canonical_quaternion(quaternion))

    # tf2's BufferCore::getLatestCommonTime, with target = parent and source = child.
    def _latest_common_time(self, target: str, source: str) -> int:
        source_chain: List[Tuple[int, str]] = []   # (newest stamp, parent) of each edge up
        common = None
        frame, walked = source, [source]
        while frame in self._edges:
            stamp, parent = self._edges[frame].latest()
            common = _earlier(common, stamp)
            source_chain.append((stamp, parent))
            frame = parent
            if frame == target:
                return common or 0
            self._check_depth(walked, frame, target, source)
        source_root = frame
        source_parents = [parent for _, parent in source_chain]
        frame, walked, common = target, [target], None
        common_parent = None
        while frame in self._edges:
            stamp, parent = self._edges[frame].latest()
            common = _earlier(common, stamp)
            if parent in source_parents:
                common_parent = parent
                break
            frame = parent
            if frame == source:
                return common or 0
            self._check_depth(walked, frame, target, source)
        if common_parent is None:
            raise NotConnectedError(
                f'frames {target!r} and {source!r} are not connected: the tree of {source!r} '
                f'ends at {source_root!r}, the tree of {target!r} at {frame!r}')
        for stamp, parent in source_chain:
            common = _earlier(common, stamp)
            if parent == common_parent:
                break
        return common or 0

    # tf2's BufferCore::walkToTopParent with TransformAccum, rotations only.
    def _walk(self, target: str, source: str, time_ns: int) -> np.ndarray:
        source_to_top = _IDENTITY
        frame = top_parent = source
        walked = [source]
        extrapolation: Optional[ExtrapolationError] = None
        while True:
            edge = self._edges.get(frame)
            if edge is None:
                top_parent = frame
                break
            try:
                sample = edge.data(time_ns, frame)
            except ExtrapolationError as exc:   # there may still be a path from the target
                top_parent, extrapolation = frame, exc
                break
            if frame == target:
                return source_to_top
            source_to_top = conversions.quaternion_product(sample.quaternion, source_to_top)
            top_parent, frame = frame, sample.parent
            self._check_depth(walked, frame, target, source)
        target_to_top = _IDENTITY
        frame, walked = target, [target]
        while frame != top_parent:
            edge = self._edges.get(frame)
            if edge is None:
                break
            try:
                sample = edge.data(time_ns, frame)
            except ExtrapolationError as exc:
                raise ExtrapolationError(f'{exc}, looking up {source!r} in {target!r}') from None
            if frame == source:
                return conversions.quaternion_conjugate(target_to_top)
            target_to_top = conversions.quaternion_product(sample.quaternion, target_to_top)
            frame = sample.parent
            self._check_depth(walked, frame, target, source)
        if frame != top_parent:
            if extrapolation is not None:
                raise ExtrapolationError(f'{extrapolation}, looking up {source!r} in {target!r}')
            raise NotConnectedError(
                f'frames {target!r} and {source!r} are not connected at time '
                f'{seconds_text(time_ns)} s: the tree of {source!r} ends at {top_parent!r}, '
                f'the tree of {target!r} at {frame!r}')
        return conversions.quaternion_product(
            conversions.quaternion_conjugate(target_to_top), source_to_top)

    @staticmethod
    def _check_depth(walked: List[str], frame: str, target: str, source: str) -> None:
        """Record one step of a walk to ``frame``; CycleError on a loop or past the depth limit."""
        if frame in walked:
            loop = walked[walked.index(frame):] + [frame]
            raise CycleError(f'the TF tree contains a loop: {" -> ".join(reversed(loop))} '
                             f'(parent -> child), looking up {source!r} in {target!r}')
        walked.append(frame)
        if len(walked) > MAX_GRAPH_DEPTH + 1:
            raise CycleError(f'the TF tree is deeper than {MAX_GRAPH_DEPTH} edges above '
                             f'{walked[0]!r} (tf2 takes that for a loop), looking up '
                             f'{source!r} in {target!r}')


def _stripped(frame: str) -> str:
    """tf2's ``stripSlash``: the frame name without one leading ``/``."""
    return frame[1:] if frame.startswith('/') else frame


def _earlier(common: Optional[int], stamp: int) -> Optional[int]:
    """Return the minimum of the stamps so far; stamp 0 (a static edge) does not count."""
    if stamp == 0:
        return common
    return stamp if common is None else min(common, stamp)
