"""
Tests of rotation_node.tf_buffer: tf2's lookupTransform semantics, for orientations.

The oracle is independent of the buffer: scipy's ``Rotation`` and ``Slerp``
interpolate each edge at the lookup time computed here from the known sample
stamps (the minimum of the dynamic edges' newest stamps), and compose the
chain; the expectations on pruning, exact stamps and single samples follow
tf2's ``TimeCache`` (``cache.cpp``) and ``BufferCore`` (``buffer_core.cpp``).
"""
import numpy as np
import pytest
from rotation_node.tf_buffer import (
    CycleError, DEFAULT_CACHE_TIME_NS, ExtrapolationError, MAX_GRAPH_DEPTH, NotConnectedError,
    RejectedTransformError, TfLookupError, TfOrientationBuffer, UnknownFrameError)
from scipy.spatial.transform import Rotation, Slerp

S = 1_000_000_000                  # nanoseconds per second
T0 = 1_700_000_000 * S + 123_456   # a wall-clock origin: stamps are integer nanoseconds
ANGLE_BOUND = 1e-14                # rad: composed, interpolated chains (worst seen 3.5e-15)


def angle_between(q, expected: Rotation) -> float:
    """Geodesic angle (rad) between the buffer's quaternion and the oracle's rotation."""
    return (Rotation.from_quat(q) * expected.inv()).magnitude()


class Edge:
    """Samples of one dynamic edge and scipy's interpolation of them (the oracle)."""

    def __init__(self, parent, child):
        self.parent, self.child = parent, child
        self.stamps, self.rotations = [], []

    def add(self, buffer, stamp_ns, rotation):
        buffer.insert(self.parent, self.child, stamp_ns, rotation.as_quat())
        self.stamps.append(stamp_ns)
        self.rotations.append(rotation.as_quat())

    def at(self, stamp_ns) -> Rotation:
        stamps = np.array(self.stamps) - T0   # exact integers, then seconds
        if stamp_ns in self.stamps:
            return Rotation.from_quat(self.rotations[self.stamps.index(stamp_ns)])
        return Slerp(stamps * 1e-9, Rotation.from_quat(self.rotations))((stamp_ns - T0) * 1e-9)


def random_walk(rng, n, step=0.3):
    """``n`` rotations, each within ``step`` rad of the previous one (a moving frame)."""
    steps = Rotation.from_rotvec(rng.normal(scale=step / 2, size=(n, 3)))
    current, out = Rotation.random(random_state=rng), []
    for k in range(n):
        current = current * steps[k]
        out.append(current)
    return out


@pytest.mark.slow
def test_three_edge_chain_matches_scipy_after_every_sample(rng):
    # map -> odom at 10 Hz, odom -> base_link at 30 Hz (other phase), base_link -> imu static.
    buffer = TfOrientationBuffer()
    static = Rotation.random(random_state=rng)
    buffer.insert('base_link', 'imu_link', 0, static.as_quat(), static=True)
    slow, fast = Edge('map', 'odom'), Edge('odom', 'base_link')
    events = ([(T0 + k * S // 10, slow) for k in range(40)]
              + [(T0 + 7_000_001 + k * S // 30, fast) for k in range(120)])
    events.sort(key=lambda event: event[0])
    rotations = {slow: iter(random_walk(rng, 40)), fast: iter(random_walk(rng, 120))}
    checked = 0
    for stamp, edge in events:
        edge.add(buffer, stamp, next(rotations[edge]))
        if not (slow.stamps and fast.stamps):
            with pytest.raises(TfLookupError):
                buffer.lookup_orientation('map', 'imu_link')
            continue
        common = min(slow.stamps[-1], fast.stamps[-1])
        if common < max(slow.stamps[0], fast.stamps[0]):
            # One edge's first sample is newer than the other's newest: tf2 would
            # have to extrapolate it into the past.
            late = slow if slow.stamps[0] > common else fast
            with pytest.raises(ExtrapolationError, match=f'{late.parent} -> {late.child}'):
                buffer.lookup_orientation('map', 'imu_link')
            continue
        result = buffer.lookup_orientation('map', 'imu_link')
        assert result.stamp_ns == common
        expected = slow.at(common) * fast.at(common) * static
        assert angle_between(result.quaternion, expected) < ANGLE_BOUND
        assert result.quaternion[3] >= 0.0 and abs(np.linalg.norm(result.quaternion) - 1) < 4e-16
        checked += 1
    assert checked > 150


def test_reversed_lookup_is_the_inverse_at_the_same_time(rng):
    buffer = TfOrientationBuffer()
    a, b = Edge('map', 'odom'), Edge('odom', 'base_link')
    for k, rotation in enumerate(random_walk(rng, 5)):
        a.add(buffer, T0 + k * S, rotation)
    for k, rotation in enumerate(random_walk(rng, 7)):
        b.add(buffer, T0 + k * S // 2 + 1, rotation)
    forward = buffer.lookup_orientation('map', 'base_link')
    backward = buffer.lookup_orientation('base_link', 'map')
    assert forward.stamp_ns == backward.stamp_ns == T0 + 3 * S + 1
    expected = a.at(forward.stamp_ns) * b.at(forward.stamp_ns)
    assert angle_between(forward.quaternion, expected) < ANGLE_BOUND
    assert angle_between(backward.quaternion, expected.inv()) < ANGLE_BOUND


def test_chains_through_a_common_ancestor(rng):
    # map -> odom -> base_link -> arm -> hand, base_link -> camera, map -> landmark.
    buffer = TfOrientationBuffer()
    edges = {name: Edge(*name.split('>'))
             for name in ('map>odom', 'odom>base_link', 'base_link>arm', 'arm>hand')}
    static = {name: Rotation.random(random_state=rng)
              for name in ('base_link>camera', 'map>landmark')}
    for name, rotation in static.items():
        buffer.insert(*name.split('>'), 0, rotation.as_quat(), static=True)
    periods = {'map>odom': S // 5, 'odom>base_link': S // 50, 'base_link>arm': S // 20,
               'arm>hand': S // 100}
    for name, edge in edges.items():
        rotations = random_walk(rng, 30)
        for k in range(30):
            edge.add(buffer, T0 + 3 + k * periods[name], rotations[k])
    latest = {name: edge.stamps[-1] for name, edge in edges.items()}

    def chain(*names):
        rotation = Rotation.identity()
        for name in names:
            rotation = rotation * (static[name] if name in static
                                   else edges[name].at(common))
        return rotation

    # hand in camera: up from hand to base_link, down to camera; map -> odom not involved.
    common = min(latest['base_link>arm'], latest['arm>hand'])
    result = buffer.lookup_orientation('camera', 'hand')
    assert result.stamp_ns == common
    expected = static['base_link>camera'].inv() * chain('base_link>arm', 'arm>hand')
    assert angle_between(result.quaternion, expected) < ANGLE_BOUND
    # camera in landmark: the common ancestor is the root, every dynamic edge above camera.
    common = min(latest['map>odom'], latest['odom>base_link'])
    result = buffer.lookup_orientation('landmark', 'camera')
    assert result.stamp_ns == common
    expected = static['map>landmark'].inv() * chain('map>odom', 'odom>base_link',
                                                    'base_link>camera')
    assert angle_between(result.quaternion, expected) < ANGLE_BOUND
    # arm in hand (the parent below the child) and hand in odom (several edges up).
    common = latest['arm>hand']
    result = buffer.lookup_orientation('hand', 'arm')
    assert result.stamp_ns == common
    assert angle_between(result.quaternion, edges['arm>hand'].at(common).inv()) < ANGLE_BOUND
    common = min(latest[name] for name in ('odom>base_link', 'base_link>arm', 'arm>hand'))
    result = buffer.lookup_orientation('odom', 'hand')
    assert result.stamp_ns == common
    expected = chain('odom>base_link', 'base_link>arm', 'arm>hand')
    assert angle_between(result.quaternion, expected) < ANGLE_BOUND


def test_lookup_at_a_given_time_interpolates_every_edge(rng):
    buffer = TfOrientationBuffer()
    a, b = Edge('map', 'odom'), Edge('odom', 'base_link')
    for k, rotation in enumerate(random_walk(rng, 11, step=1.0)):
        a.add(buffer, T0 + k * S, rotation)
        b.add(buffer, T0 + k * S + S // 3, rotation.inv())
    for stamp in (T0 + S // 3, T0 + 4 * S + 1, T0 + 7 * S + S // 2, T0 + 10 * S):
        result = buffer.lookup_orientation('map', 'base_link', stamp)
        assert result.stamp_ns == stamp
        assert angle_between(result.quaternion, a.at(stamp) * b.at(stamp)) < ANGLE_BOUND
    with pytest.raises(ExtrapolationError, match='into the past'):
        buffer.lookup_orientation('map', 'base_link', T0 + S // 4)   # before odom -> base_link
    with pytest.raises(ExtrapolationError, match='into the future'):
        buffer.lookup_orientation('map', 'base_link', T0 + 10 * S + 1)


def test_a_sample_at_the_lookup_time_is_returned_as_it_is():
    # tf2 returns the stored sample at an exact stamp; exact values show any arithmetic.
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.5, 0.5, 0.5, 0.5))
    buffer.insert('map', 'odom', T0 + S, (0.0, 0.0, 0.6, 0.8))
    buffer.insert('map', 'odom', T0 + 2 * S, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('odom', 'base_link', T0 + S, (0.0, 0.0, 0.0, 1.0))
    result = buffer.lookup_orientation('map', 'base_link')
    assert result.stamp_ns == T0 + S
    np.testing.assert_array_equal(result.quaternion, [0.0, 0.0, 0.6, 0.8])
    np.testing.assert_array_equal(buffer.lookup_orientation('map', 'odom', T0).quaternion,
                                  [0.5, 0.5, 0.5, 0.5])


def test_one_sample_answers_only_at_its_stamp():
    buffer = TfOrientationBuffer()
    q = Rotation.from_euler('xyz', (0.1, 0.2, 0.3)).as_quat()
    buffer.insert('map', 'base_link', T0, q)
    result = buffer.lookup_orientation('map', 'base_link')
    assert result.stamp_ns == T0
    assert angle_between(result.quaternion, Rotation.from_quat(q)) < 1e-16
    assert buffer.lookup_orientation('map', 'base_link', T0).stamp_ns == T0
    with pytest.raises(ExtrapolationError, match='only time 1700000000.000123456 s'):
        buffer.lookup_orientation('map', 'base_link', T0 + 1)
    # Two edges each with one sample at different stamps: no common time with data.
    buffer.insert('base_link', 'imu_link', T0 + 5, q)
    with pytest.raises(ExtrapolationError, match='base_link -> imu_link'):
        buffer.lookup_orientation('map', 'imu_link')


def test_static_chain_has_time_zero_and_the_newest_static_value():
    buffer = TfOrientationBuffer()
    buffer.insert('base_link', 'imu_link', T0, (0.0, 0.0, 1.0, 0.0), static=True)
    buffer.insert('imu_link', 'sensor', 5, (1.0, 0.0, 0.0, 0.0), static=True)
    result = buffer.lookup_orientation('base_link', 'sensor')
    assert result.stamp_ns == 0
    np.testing.assert_allclose(result.quaternion, [0.0, 1.0, 0.0, 0.0], atol=1e-16)
    buffer.insert('base_link', 'imu_link', T0 + S, (0.0, 0.0, 0.0, 1.0), static=True)
    np.testing.assert_allclose(buffer.lookup_orientation('base_link', 'sensor').quaternion,
                               [1.0, 0.0, 0.0, 0.0], atol=1e-16)
    # A static edge holds at every time, a lookup at a given time included.
    assert buffer.lookup_orientation('base_link', 'sensor', T0 - S).stamp_ns == T0 - S


def test_an_edge_that_turns_static_forgets_its_history():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('map', 'odom', T0 + S, (0.0, 0.0, 1.0, 0.0))
    buffer.insert('map', 'odom', T0, (1.0, 0.0, 0.0, 0.0), static=True)
    result = buffer.lookup_orientation('map', 'odom')
    assert result.stamp_ns == 0
    np.testing.assert_array_equal(result.quaternion, [1.0, 0.0, 0.0, 0.0])
    buffer.insert('map', 'odom', T0 + 2 * S, (0.0, 1.0, 0.0, 0.0))   # dynamic again
    assert buffer.lookup_orientation('map', 'odom').stamp_ns == T0 + 2 * S
    with pytest.raises(ExtrapolationError):
        buffer.lookup_orientation('map', 'odom', T0 + S)


def test_cache_keeps_ten_seconds_behind_the_newest_sample_pruned_before_insertion(rng):
    assert DEFAULT_CACHE_TIME_NS == 10 * S
    buffer = TfOrientationBuffer()
    edge = Edge('map', 'odom')
    for k, rotation in enumerate(random_walk(rng, 21)):
        edge.add(buffer, T0 + k * S, rotation)
    # Inserting the sample at 20 s pruned against the newest stamp before it, 19 s:
    # the samples from 9 s on remain (tf2's TimeCache::insertData).
    assert angle_between(buffer.lookup_orientation('map', 'odom', T0 + 9 * S).quaternion,
                         edge.at(T0 + 9 * S)) < ANGLE_BOUND
    assert angle_between(buffer.lookup_orientation('map', 'odom', T0 + 9 * S + S // 2).quaternion,
                         edge.at(T0 + 9 * S + S // 2)) < ANGLE_BOUND
    with pytest.raises(ExtrapolationError, match='into the past'):
        buffer.lookup_orientation('map', 'odom', T0 + 9 * S - 1)
    # A sample older than the newest minus the cache time is ignored, as tf2 does.
    with pytest.raises(RejectedTransformError, match='cache time') as rejected:
        buffer.insert('map', 'odom', T0 + 10 * S - 1, (0.0, 0.0, 0.0, 1.0))
    assert rejected.value.reason == 'old_data'
    buffer.insert('map', 'odom', T0 + 10 * S, (0.0, 0.0, 0.0, 1.0))   # exactly the limit
    # That insertion pruned against 20 s: 9 s is gone, 10 s is there, twice now. At the
    # earliest stamp tf2 answers with the sample inserted first, elsewhere with the
    # newest insertion (TimeCache::findClosest).
    with pytest.raises(ExtrapolationError):
        buffer.lookup_orientation('map', 'odom', T0 + 9 * S)
    assert angle_between(buffer.lookup_orientation('map', 'odom', T0 + 10 * S).quaternion,
                         edge.at(T0 + 10 * S)) < 1e-16
    buffer.insert('map', 'odom', T0 + 11 * S, (0.0, 0.0, 1.0, 0.0))
    buffer.insert('map', 'odom', T0 + 11 * S, (0.0, 1.0, 0.0, 0.0))
    np.testing.assert_array_equal(buffer.lookup_orientation('map', 'odom', T0 + 11 * S)
                                  .quaternion, [0.0, 1.0, 0.0, 0.0])


def test_prune_before_insert_is_visible_in_a_latest_lookup(rng):
    # tf2 prunes against the newest stamp BEFORE the new sample: with samples at 0 s and
    # 20 s, the edge still interpolates at 5 s until its next insertion.
    buffer = TfOrientationBuffer()
    slow, fast = Edge('map', 'odom'), Edge('odom', 'base_link')
    first, second = random_walk(rng, 2, step=2.0)
    slow.add(buffer, T0, first)
    slow.add(buffer, T0 + 20 * S, second)
    fast.add(buffer, T0 + 5 * S, Rotation.random(random_state=rng))
    result = buffer.lookup_orientation('map', 'base_link')
    assert result.stamp_ns == T0 + 5 * S
    expected = slow.at(T0 + 5 * S) * fast.at(T0 + 5 * S)
    assert angle_between(result.quaternion, expected) < ANGLE_BOUND
    slow.add(buffer, T0 + 21 * S, second)   # now 0 s is pruned
    with pytest.raises(ExtrapolationError, match='into the past'):
        buffer.lookup_orientation('map', 'base_link')


def test_shorter_cache_time():
    buffer = TfOrientationBuffer(cache_time_ns=S)
    for k in range(5):   # the last insertion prunes against 1.5 s: 0 s goes
        buffer.insert('map', 'odom', T0 + k * S // 2, (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(ExtrapolationError):
        buffer.lookup_orientation('map', 'odom', T0)
    assert buffer.lookup_orientation('map', 'odom', T0 + S // 2).stamp_ns == T0 + S // 2
    with pytest.raises(ValueError, match='cache_time_ns'):
        TfOrientationBuffer(cache_time_ns=-1)


def test_unknown_frames_are_named():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(UnknownFrameError) as error:
        buffer.lookup_orientation('map', 'base_link')
    assert str(error.value) == ("frame 'base_link' (child) does not exist (no transform names "
                                "it), looking up 'base_link' in 'map'")
    assert error.value.reason == 'unknown_frame'
    with pytest.raises(UnknownFrameError) as error:
        buffer.lookup_orientation('world', 'base_link')
    assert str(error.value).startswith(
        "frames 'world' (parent) and 'base_link' (child) do not exist (no transform names them)")
    assert 'odom' in buffer and 'base_link' not in buffer


def test_frames_of_different_trees_are_not_connected():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('odom', 'base_link', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('world', 'camera', 0, (0.0, 0.0, 0.0, 1.0), static=True)
    with pytest.raises(NotConnectedError, match="'camera' and 'base_link'.*ends at 'map'") as e:
        buffer.lookup_orientation('camera', 'base_link')
    assert e.value.reason == 'not_connected'
    with pytest.raises(NotConnectedError, match="'odom' and 'world'"):
        buffer.lookup_orientation('odom', 'world')


def test_a_cycle_is_an_error_naming_the_loop():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('odom', 'base_link', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('base_link', 'odom2', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('odom2', 'map', T0, (0.0, 0.0, 0.0, 1.0))   # closes map -> ... -> map
    buffer.insert('world', 'camera', T0, (0.0, 0.0, 0.0, 1.0))
    loop = 'loop: base_link -> odom2 -> map -> odom -> base_link'
    with pytest.raises(CycleError, match=loop) as e:
        buffer.lookup_orientation('camera', 'base_link')
    assert e.value.reason == 'cycle'
    with pytest.raises(CycleError):
        buffer.lookup_orientation('base_link', 'camera')
    # tf2 walks up from the child and stops at the parent: a lookup inside the loop answers.
    assert buffer.lookup_orientation('map', 'base_link').stamp_ns == T0


def test_depth_limit_is_tf2s():
    buffer = TfOrientationBuffer()
    for k in range(MAX_GRAPH_DEPTH + 1):
        buffer.insert(f'f{k}', f'f{k + 1}', 0, (0.0, 0.0, 0.0, 1.0), static=True)
    assert buffer.lookup_orientation('f0', f'f{MAX_GRAPH_DEPTH}').stamp_ns == 0
    with pytest.raises(CycleError, match='deeper than 1000 edges'):
        buffer.lookup_orientation('f0', f'f{MAX_GRAPH_DEPTH + 1}')


def test_a_frame_that_changes_parent_is_followed_at_the_lookup_time():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('map', 'world', T0, (0.0, 0.0, 1.0, 0.0))
    buffer.insert('odom', 'base_link', T0, (1.0, 0.0, 0.0, 0.0))
    buffer.insert('world', 'base_link', T0 + S, (0.0, 1.0, 0.0, 0.0))
    buffer.insert('map', 'odom', T0 + 2 * S, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('map', 'world', T0 + 2 * S, (0.0, 0.0, 1.0, 0.0))
    # Between two samples with different parents, tf2 takes the older one, uninterpolated.
    at = buffer.lookup_orientation('map', 'base_link', T0 + S // 2)
    np.testing.assert_array_equal(at.quaternion, [1.0, 0.0, 0.0, 0.0])
    # At the newest stamp, the parent is world: z(pi) then y(pi) = x(pi).
    latest = buffer.lookup_orientation('map', 'base_link')
    assert latest.stamp_ns == T0 + S
    np.testing.assert_allclose(latest.quaternion, [1.0, 0.0, 0.0, 0.0], atol=1e-16)


@pytest.mark.parametrize('parent, child, quaternion, translation, reason', [
    ('base_link', 'base_link', (0, 0, 0, 1), (0, 0, 0), 'self_transform'),
    ('/base_link', 'base_link', (0, 0, 0, 1), (0, 0, 0), 'self_transform'),
    ('map', '', (0, 0, 0, 1), (0, 0, 0), 'no_child_frame_id'),
    ('', 'odom', (0, 0, 0, 1), (0, 0, 0), 'no_frame_id'),
    ('map', 'odom', (0, 0, float('nan'), 1), (0, 0, 0), 'nan_input'),
    ('map', 'odom', (0, 0, 0, 1), (0, float('nan'), 0), 'nan_input'),
    ('map', 'odom', (0, 0, 0, 1.006), (0, 0, 0), 'denormalized_quaternion'),
    ('map', 'odom', (0, 0, 0, float('inf')), (0, 0, 0), 'denormalized_quaternion'),
    ('map', 'odom', (0, 0, 0, 0), (0, 0, 0), 'denormalized_quaternion'),
])
def test_samples_tf2_ignores_are_rejected(parent, child, quaternion, translation, reason):
    buffer = TfOrientationBuffer()
    with pytest.raises(RejectedTransformError, match='ignored') as error:
        buffer.insert(parent, child, T0, quaternion, translation=translation)
    assert error.value.reason == reason
    assert 'odom' not in buffer and 'map' not in buffer


def test_leading_slash_is_dropped_and_near_unit_quaternions_accepted():
    buffer = TfOrientationBuffer()
    buffer.insert('/map', '/odom', T0, (0.0, 0.0, 0.0, 1.004))   # |q|^2 - 1 = 0.008
    result = buffer.lookup_orientation('map', 'odom')
    np.testing.assert_array_equal(result.quaternion, [0.0, 0.0, 0.0, 1.0])


@pytest.mark.parametrize('parent, child, stamp, name', [
    ('map', 'map', 0, '`parent` and `child`'),
    ('', 'odom', 0, '`parent`'),
    ('map', '/odom', 0, '`child`'),
    ('map', 'odom', -1, '`stamp_ns`'),
    ('map', 'odom', 1.5, '`stamp_ns`'),
])
def test_bad_lookup_arguments_are_value_errors_naming_them(parent, child, stamp, name):
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=name):
        buffer.lookup_orientation(parent, child, stamp)


def test_duplicate_samples_are_kept_once_and_equal_stamps_take_the_newest():
    buffer = TfOrientationBuffer()
    buffer.insert('map', 'odom', T0, (0.0, 0.0, 0.0, 1.0))
    buffer.insert('map', 'odom', T0 + S, (0.0, 0.0, 1.0, 0.0))
    buffer.insert('map', 'odom', T0 + S, (0.0, 0.0, 1.0, 0.0))
    buffer.insert('map', 'odom', T0 + S, (1.0, 0.0, 0.0, 0.0))   # same stamp, newer data
    np.testing.assert_array_equal(buffer.lookup_orientation('map', 'odom').quaternion,
                                  [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='stamp_ns'):
        buffer.insert('map', 'odom', 1.0, (0.0, 0.0, 0.0, 1.0))
