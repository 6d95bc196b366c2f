"""
Orientations from a TF tree, with the semantics of tf2's ``BufferCore`` (docs/tf.md).

:class:`TfOrientationBuffer` is a port of tf2's lookup (``lookupTransform``,
``walkToTopParent``, ``getLatestCommonTime``, ``TimeCache``) restricted to rotations:
translations are checked as tf2 checks them but not stored. A "latest" lookup (time 0) is at
the minimum over the chain's dynamic edges of their newest stamp (stamp-0 samples do not
count; a static-only chain has time 0); dynamic edges are slerped to it and never
extrapolated; each keeps ``cache_time_ns`` behind its newest sample. A frame may change
parent over time; an edge that turns static (or back) starts afresh.

Errors are typed and carry a ``reason`` for counters and a message naming the frames.
Quaternions are ``(x, y, z, w)``, normalised when stored; times are integer nanoseconds.
"""
from bisect import bisect_right
import math
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Set, Tuple, Union

import numpy as np

from rotation_node import conversions
from rotation_node.errors import RotationNodeError
from rotation_node.kinematics import slerp
from rotation_node.wire.stamps import seconds_text, stamp_ns as _stamp_ns

#: How long a dynamic edge keeps its samples behind the newest one (tf2's default, 10 s).
DEFAULT_CACHE_TIME_NS = 10_000_000_000
#: Longest walk from a frame towards the root, in edges; tf2 calls a deeper one a loop.
MAX_GRAPH_DEPTH = 1000
#: tf2 ignores a sample whose squared quaternion norm differs from 1 by this much or more.
QUATERNION_NORM_TOLERANCE = 10e-3

_IDENTITY = np.array((0.0, 0.0, 0.0, 1.0))


class TfError(RotationNodeError):
    """A TF sample or lookup could not be used; ``reason`` (str) names the kind, for counters."""

    reason: str


class RejectedTransformError(TfError):
    """A sample tf2 would ignore (self transform, NaN, old data...); ``reason`` names why."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


class TfLookupError(TfError):
    """A lookup has no answer; each subclass's ``reason`` names why."""


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
    """The answer of a lookup: its time (ns) and the child's unit orientation in the parent."""

    stamp_ns: int            # for "latest", the chain's latest common time (0: static only)
    quaternion: np.ndarray   # (x, y, z, w), w >= 0: child coordinates to parent coordinates


class _Sample(NamedTuple):
    stamp_ns: int
    quaternion: np.ndarray
    parent: str


class _StaticEdge:
    """tf2's ``StaticCache``: one sample, valid at every time."""

    def __init__(self, sample: _Sample):
        self.sample = sample

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
        """Insert a sample; False if it is older than the cache time allows."""
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


class TfOrientationBuffer:
    """
    The rotations of a TF tree over time, looked up as tf2 looks up transforms.

    ``cache_time_ns``: how long each dynamic edge keeps samples behind its newest one. A
    leading ``/`` of a sample's frame is dropped (tf2's ``stripSlash``); names are otherwise
    compared exactly.
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
        """Tell whether ``frame`` appears in a sample (as a parent or a child)."""
        return frame in self._frames

    def insert(self, parent: str, child: str, stamp_ns: int, quaternion: Sequence[float], *,
               static: bool = False,
               translation: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """
        Add one sample of the edge ``parent -> child`` (one TransformStamped's fields).

        ``quaternion`` is the orientation of ``child`` in ``parent``; ``static`` (``/tf_static``)
        makes it valid at every time, replacing the edge; ``translation`` is only checked for
        NaN. RejectedTransformError where tf2 would ignore the sample (``reason``:
        ``self_transform``, ``no_child_frame_id``, ``no_frame_id``, ``nan_input``,
        ``denormalized_quaternion``, ``old_data``); the edge is then unchanged (an old
        sample's frames are known from then on, as in tf2).
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
        if static or not isinstance(edge, _DynamicEdge):
            self._edges[child] = _StaticEdge(sample) if static else _DynamicEdge(sample)
        elif not edge.insert(sample, self.cache_time_ns):
            newest = edge.latest()[0]
            raise RejectedTransformError(
                'old_data',
                f'transform {parent!r} -> {child!r} ignored: stamp {seconds_text(stamp_ns)} s is '
                f'more than the cache time {seconds_text(self.cache_time_ns)} s before the '
                f'newest sample of that edge ({seconds_text(newest)} s)')

    def insert_transforms(self, transforms: Sequence[Any], *,
                          static: bool = False) -> List[RejectedTransformError]:
        """Add the ``TransformStamped`` of a TFMessage; return those tf2 would ignore, why."""
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
        Return the orientation of ``child`` in ``parent``: tf2's ``lookupTransform``.

        ``stamp_ns`` 0 is tf2's ``Time(0)``, "latest". ValueError for frame names that are
        empty, start with ``/`` or are equal; else the lookup errors: UnknownFrameError,
        NotConnectedError, CycleError, ExtrapolationError.
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
        """Record a walk's step to ``frame``; CycleError on a loop or past the depth limit."""
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
    """Return the minimum of the stamps so far; stamp 0 (static) does not count."""
    if stamp == 0:
        return common
    return stamp if common is None else min(common, stamp)
