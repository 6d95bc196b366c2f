"""Tests of rotation_node.scene.spec: loading and validating scene files."""
import copy
import glob
import math
import os

import pytest

from rotation_node.errors import SceneError
from rotation_node.scene import effects, spec

SCENES = sorted(glob.glob(os.path.join(os.path.dirname(__file__), '..', 'config', 'scenes',
                                       '*.yaml')))

MOTIONS = {
    'constant_rate': {'type': 'constant_rate', 'orientation': [0, 0, 0, 1],
                      'angular_velocity': [0.1, 0.2, 0.3]},
    'coning': {'type': 'coning', 'half_angle': 0.2, 'frequency': 3.0},
    'torque_free': {'type': 'torque_free', 'inertia': [1, 2, 3],
                    'orientation': [0, 0, 0, 1], 'angular_velocity': [0, 1, 0]},
    'euler_sweep': {'type': 'euler_sweep', 'sequence': 'ZYX',
                    'start': [0, 1, 0], 'end': [0, 2, 0]},
}

DELETE = object()


def scene_dict(kind='coning', changes=None):
    """Return a valid scene as parsed YAML with ``changes``: {dotted key path: value or DELETE}."""
    data = {'duration': 1.0, 'rate': 10.0, 'motion': copy.deepcopy(MOTIONS[kind]),
            'effects': {}}
    for dotted, value in (changes or {}).items():
        *parents, key = dotted.split('.')
        node = data
        for parent in parents:
            node = node.setdefault(parent, {})
        if value is DELETE:
            del node[key]
        else:
            node[key] = value
    return data


@pytest.mark.parametrize('path', SCENES, ids=os.path.basename)
def test_shipped_scenes_are_valid(path):
    scene = spec.load_scene(path)
    assert isinstance(scene.motion, tuple(spec.MOTIONS.values()))
    assert scene.sample_count >= 2


def test_shipped_scenes_cover_the_issue():
    """Constant rate, coning, tumbling box, gimbal-lock sweep, every effect on."""
    scenes = [spec.load_scene(path) for path in SCENES]
    kinds = {scene.motion.type for scene in scenes}
    assert kinds == set(spec.MOTIONS)
    assert any(set(scene.effects) == set(spec.EFFECT_PARAMETERS) for scene in scenes)


def test_defaults_of_optional_keys():
    scene = spec.scene_from_dict(scene_dict(changes={'effects': DELETE}))
    assert (scene.topic, scene.frame_id) == ('/imu', 'imu_link')
    assert scene.start_time == spec.DEFAULT_START_TIME
    assert scene.effects == {}
    assert scene.motion == spec.Coning(half_angle=0.2, frequency=3.0)


def test_reference_only_when_asked_and_its_defaults():
    assert spec.scene_from_dict(scene_dict()).reference is None
    reference = spec.scene_from_dict(scene_dict(changes={'reference': {'rate': 120}})).reference
    assert reference == spec.Reference(
        rate=120.0, topic='/reference/pose', frame_id='mocap', message='pose', time_offset=0.0,
        mounting=(0.0, 0.0, 0.0, 1.0), world_alignment=(0.0, 0.0, 0.0, 1.0),
        orientation_noise=0.0)


def test_effect_defaults():
    scene = spec.scene_from_dict(scene_dict(changes={'effects': {
        'orientation_unknown': None, 'gyro_bias': {},
        'nan_bursts': {'probability': 0.1, 'length': 2}}}))
    assert scene.effects['orientation_unknown'].probability == 1.0
    assert scene.effects['gyro_bias'] == spec.GyroBias(constant=(0.0, 0.0, 0.0), random_walk=0.0)
    assert scene.effects['nan_bursts'].fields == ('orientation', 'angular_velocity')


def test_orientation_is_normalised_within_tolerance():
    q = [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5) * (1 + 5e-7)]
    motion = spec.scene_from_dict(scene_dict('constant_rate', {'motion.orientation': q})).motion
    assert math.hypot(*motion.orientation) == pytest.approx(1.0, abs=1e-15)


def test_effect_registries_agree():
    """Every effect the scene format accepts has a function, and no other."""
    assert set(effects.EFFECTS) == set(spec.EFFECT_PARAMETERS)


@pytest.mark.parametrize('duration, rate, expected', [
    (4.0, 100.0, 401),     # end point included
    (0.3, 10.0, 4),        # 0.3 * 10 = 3.0000000000000004
    (0.7, 10.0, 8),        # 0.7 * 10 = 7.000000000000001
    (2.9, 10.0, 30),       # 28.999999999999996
    (0.05, 10.0, 1),       # shorter than one period: the first sample only
    (1.0, 3.0, 4),
])
def test_sample_count(duration, rate, expected):
    assert spec.sample_count(duration, rate) == expected


BAD_SCENES = [
    # (motion, changes, key path the error must start with)
    ('coning', {'rate': -1.0}, 'rate'),
    ('coning', {'rate': 0}, 'rate'),
    ('coning', {'rate': True}, 'rate'),
    ('coning', {'rate': '100'}, 'rate'),
    ('coning', {'duration': float('inf')}, 'duration'),
    ('coning', {'duration': 10**400}, 'duration'),
    ('coning', {'duration': DELETE}, 'duration'),
    ('coning', {'duration': 1e6, 'rate': 1e3}, 'duration'),
    ('coning', {'speed': 1.0}, 'speed'),
    ('coning', {'topic': 'imu'}, 'topic'),
    ('coning', {'topic': '/imu/'}, 'topic'),
    ('coning', {'topic': '/2imu'}, 'topic'),
    ('coning', {'topic': '/truth/orientation'}, 'topic'),
    ('coning', {'frame_id': ''}, 'frame_id'),
    ('coning', {'frame_id': '/imu_link'}, 'frame_id'),
    ('coning', {'start_time': -1.0}, 'start_time'),
    ('coning', {'start_time': 2.0**31}, 'start_time'),
    ('coning', {'motion': DELETE}, 'motion'),
    ('coning', {'motion': 'coning'}, 'motion'),
    ('coning', {'motion.type': DELETE}, 'motion.type'),
    ('coning', {'motion.type': 'wobble'}, 'motion.type'),
    ('coning', {'motion.type': ['coning']}, 'motion.type'),
    ('coning', {'motion.half_angel': 0.2}, 'motion.half_angel'),
    ('coning', {'motion.half_angle': DELETE}, 'motion.half_angle'),
    ('coning', {'motion.half_angle': 4.0}, 'motion.half_angle'),
    ('coning', {'motion.half_angle': -0.1}, 'motion.half_angle'),
    ('coning', {'motion.frequency': float('nan')}, 'motion.frequency'),
    ('coning', {'motion.orientation': [0, 0, 0, 1]}, 'motion.orientation'),
    ('constant_rate', {'motion.orientation': [0, 0, 0, 2]}, 'motion.orientation'),
    ('constant_rate', {'motion.orientation': [0, 0, 0, 0]}, 'motion.orientation'),
    ('constant_rate', {'motion.orientation': [0, 0, 1]}, 'motion.orientation'),
    ('constant_rate', {'motion.angular_velocity': [0.1, 0.2]}, 'motion.angular_velocity'),
    ('constant_rate', {'motion.angular_velocity': 0.3}, 'motion.angular_velocity'),
    ('constant_rate', {'motion.angular_velocity': [0.1, 'x', 0]}, 'motion.angular_velocity[1]'),
    ('torque_free', {'motion.inertia': [1, 2, 4]}, 'motion.inertia'),
    ('torque_free', {'motion.inertia': [0, 1, 1]}, 'motion.inertia'),
    ('torque_free', {'motion.angular_velocity': DELETE}, 'motion.angular_velocity'),
    ('euler_sweep', {'motion.sequence': 'XXY'}, 'motion.sequence'),
    ('euler_sweep', {'motion.sequence': 'XYz'}, 'motion.sequence'),
    ('euler_sweep', {'motion.sequence': 3}, 'motion.sequence'),
    ('euler_sweep', {'motion.end': [0, 1]}, 'motion.end'),
    ('coning', {'effects': ['gyro_noise']}, 'effects'),
    ('coning', {'effects.gyro_nois': {'std': 0.1}}, 'effects.gyro_nois'),
    ('coning', {'effects.gyro_noise': {}}, 'effects.gyro_noise.std'),
    ('coning', {'effects.gyro_noise': {'std': -0.1}}, 'effects.gyro_noise.std'),
    ('coning', {'effects.gyro_noise': {'std': 0.1, 'mean': 0}}, 'effects.gyro_noise.mean'),
    ('coning', {'effects.gyro_noise': 0.1}, 'effects.gyro_noise'),
    ('coning', {'effects.gyro_bias': {'constant': [0, 0]}}, 'effects.gyro_bias.constant'),
    ('coning', {'effects.dropped_messages': {'probability': 1.5}},
     'effects.dropped_messages.probability'),
    ('coning', {'effects.quaternion_sign_flips': {'probability': -0.1}},
     'effects.quaternion_sign_flips.probability'),
    ('coning', {'effects.non_unit_quaternions': {'scale': [2.0, 1.0]}},
     'effects.non_unit_quaternions.scale'),
    ('coning', {'effects.non_unit_quaternions': {'scale': [0.0, 1.0]}},
     'effects.non_unit_quaternions.scale'),
    ('coning', {'effects.nan_bursts': {'probability': 0.1, 'length': 0}},
     'effects.nan_bursts.length'),
    ('coning', {'effects.nan_bursts': {'probability': 0.1, 'length': 2.5}},
     'effects.nan_bursts.length'),
    ('coning', {'effects.nan_bursts': {'probability': 0.1, 'length': 2,
                                       'fields': ['linear_acceleration']}},
     'effects.nan_bursts.fields'),
    ('coning', {'effects.nan_bursts': {'probability': 0.1, 'length': 2,
                                       'fields': ['orientation', 'orientation']}},
     'effects.nan_bursts.fields'),
    ('coning', {'effects.timestamp_jitter': {'std': -1e-3}}, 'effects.timestamp_jitter.std'),
    ('coning', {'effects.orientation_unknown': {'probability': 2}},
     'effects.orientation_unknown.probability'),
    ('coning', {'reference': 120.0}, 'reference'),
    ('coning', {'reference': {}}, 'reference.rate'),
    ('coning', {'reference': {'rate': 0.0}}, 'reference.rate'),
    ('coning', {'reference': {'rate': 120.0, 'mountng': [0, 0, 0, 1]}}, 'reference.mountng'),
    ('coning', {'reference': {'rate': 120.0, 'mounting': [0, 0, 0, 2]}}, 'reference.mounting'),
    ('coning', {'reference': {'rate': 120.0, 'world_alignment': [0, 0, 1]}},
     'reference.world_alignment'),
    ('coning', {'reference': {'rate': 120.0, 'message': 'odometry'}}, 'reference.message'),
    ('coning', {'reference': {'rate': 120.0, 'orientation_noise': -0.1}},
     'reference.orientation_noise'),
    ('coning', {'reference': {'rate': 120.0, 'time_offset': 1.0}}, 'reference.time_offset'),
    ('coning', {'reference': {'rate': 120.0, 'time_offset': -1.5}}, 'reference.time_offset'),
    ('coning', {'reference': {'rate': 120.0, 'topic': '/imu'}}, 'reference.topic'),
    ('coning', {'reference': {'rate': 120.0, 'topic': '/truth/orientation'}}, 'reference.topic'),
    ('coning', {'reference': {'rate': 120.0, 'topic': 'mocap'}}, 'reference.topic'),
    ('coning', {'reference': {'rate': 120.0, 'frame_id': '/mocap'}}, 'reference.frame_id'),
    ('coning', {'reference': {'rate': 1e8}}, 'reference.rate'),
]


@pytest.mark.parametrize('motion, changes, key', BAD_SCENES,
                         ids=[f'{key}-{i}' for i, (_, _, key) in enumerate(BAD_SCENES)])
def test_bad_scene_names_the_key(motion, changes, key):
    with pytest.raises(SceneError) as info:
        spec.scene_from_dict(scene_dict(motion, changes))
    assert str(info.value).startswith(f'{key}:'), str(info.value)


def test_unknown_key_is_reported_before_missing_field():
    """A misspelt key reads as unknown, not as the required key it was meant to be."""
    data = scene_dict(changes={'motion.half_angle': DELETE, 'motion.half_angel': 0.2})
    with pytest.raises(SceneError, match=r'^motion\.half_angel: unknown key'):
        spec.scene_from_dict(data)


@pytest.mark.parametrize('changes, message', [
    ({'motion.half_angle': DELETE, 'motion.half_angel': 0.2},
     "motion.half_angel: unknown key (did you mean 'half_angle'?); expected type, half_angle"),
    ({'durration': 1.0}, "durration: unknown key (did you mean 'duration'?)"),
    ({'effects': {'gyro_noize': {'std': 0.1}}},
     "effects.gyro_noize: unknown effect (did you mean 'gyro_noise'?)"),
    ({'motion.type': 'conning'}, "motion.type: unknown motion 'conning' (did you mean 'coning'?)"),
    ({'effects': {'zzz': {}}}, 'effects.zzz: unknown effect; expected one of'),
])
def test_an_unknown_name_names_the_nearest_valid_one(changes, message):
    with pytest.raises(SceneError) as info:
        spec.scene_from_dict(scene_dict(changes=changes))
    assert str(info.value).startswith(message)


@pytest.mark.parametrize('data', [None, [], 'duration: 1'])
def test_scene_must_be_a_mapping(data):
    with pytest.raises(SceneError, match='^scene: expected a mapping'):
        spec.scene_from_dict(data)


@pytest.mark.parametrize('text, message', [
    ('duration: 1.0\nrate: [10\n', 'invalid YAML'),
    ('duration: 1.0\nrate: 10\nrate: 20\n', "duplicate key 'rate'"),
    ('duration: 1.0\nrate: 10\n', 'motion: missing'),
])
def test_load_scene_errors_name_the_file(tmp_path, text, message):
    path = tmp_path / 'scene.yaml'
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        spec.load_scene(path)
    assert str(info.value).startswith(f'{path}: ')
    assert message in str(info.value)


def test_exponent_without_a_dot_is_a_number(tmp_path):
    """YAML 1.2 reads 1e-3 as a number; PyYAML's YAML 1.1 would make it a string."""
    path = tmp_path / 'scene.yaml'
    path.write_text('duration: 1\nrate: 1e2\nmotion: {type: coning, half_angle: 2e-1, '
                    'frequency: -3E+0}\neffects: {gyro_noise: {std: 1e-3}}\n')
    scene = spec.load_scene(path)
    assert (scene.rate, scene.motion.half_angle, scene.motion.frequency) == (100.0, 0.2, -3.0)
    assert scene.effects['gyro_noise'].std == 0.001


def test_load_scene_missing_file(tmp_path):
    with pytest.raises(SceneError, match='cannot read it'):
        spec.load_scene(tmp_path / 'absent.yaml')
