"""
BlockPipeline (rotation_node.block_pipeline): its own contract.

Exactness against the per-message pipeline is checked end to end in
test_bag_block_convert.py.
"""
import dataclasses
import math
import types

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from rotation_node import block_pipeline, conversions, messages
from rotation_node.block_pipeline import (
    BLOCK_OUTPUTS, BLOCK_SAMPLES, block_support, BlockPipeline, SampleBlock)
from rotation_node.conversions.kernels import BATCH_SAMPLES
from rotation_node.parameters import NodeParameters
from rotation_node.pipeline import _unwrapped, ConversionPipeline


def _block(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    stamps = 1_000_000_000 + 10_000_000 * np.arange(n, dtype=np.int64)
    return SampleBlock(stamps, q, np.ones(n, dtype=bool), rng.normal(size=(n, 3)),
                       np.ones(n, dtype=bool))


def test_blocks_stay_below_the_batch_schedules():
    assert BLOCK_SAMPLES < BATCH_SAMPLES
    pipeline = BlockPipeline(ConversionPipeline(NodeParameters(input_type='imu')))
    with pytest.raises(ValueError, match='block'):
        pipeline.process_block(_block(BLOCK_SAMPLES + 1))


def test_every_block_output_is_a_registry_output():
    assert set(BLOCK_OUTPUTS) <= set(messages.OUTPUTS)


def _values_of(need, n, rng):
    """Arrays of ``n`` samples of a pipeline value: random, then the identity and a half turn."""
    if need == messages.ANGULAR_VELOCITY:
        return rng.normal(size=(n, 3))
    q = rng.normal(size=(n, 4))
    q[-2:] = [[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0]]
    if need == messages.OUTPUT_QUATERNION:   # unit, w >= 0
        q = conversions.canonical_quaternion(q)
    return q


@pytest.mark.parametrize('name', [name for name in sorted(BLOCK_OUTPUTS)
                                  if messages.OUTPUTS[name].compute is not None])
def test_each_block_output_computes_a_block_as_each_sample_alone(name):
    output = messages.OUTPUTS[name]
    params = NodeParameters(input_type='imu', outputs=(name,))
    rng = np.random.default_rng(7)
    values = [_values_of(need, 40, rng) for need in output.needs]
    block = np.asarray(output.compute(params, *values), dtype=np.float64)
    assert block.shape[0] == 40 and block.ndim == 2
    for s in range(40):
        alone = np.asarray(output.compute(params, *(value[s] for value in values)),
                           dtype=np.float64)
        assert alone.shape == block[s].shape and alone.tobytes() == block[s].tobytes(), (
            s, alone, block[s])


@pytest.mark.parametrize('values, reason', [
    ({'outputs': ('euler_stddev',)}, 'output euler_stddev'),
    ({'frames_input_body': 'frd'}, 'frame conversion'),
])
def test_block_support_names_what_has_no_block_form(values, reason):
    params = NodeParameters(input_type='pose_with_covariance', **values)
    assert reason in block_support(params)
    with pytest.raises(ValueError, match='no block form'):
        BlockPipeline(ConversionPipeline(params))


def test_an_output_added_without_a_block_form_is_left_to_the_pipeline(monkeypatch):
    added = dataclasses.replace(messages.OUTPUTS['euler'], name='euler_again')
    monkeypatch.setitem(messages.OUTPUTS, 'euler_again', added)
    # As the parameters will be once the output is in their choices.
    params = types.SimpleNamespace(**dataclasses.asdict(NodeParameters(input_type='imu')))
    params.outputs = ('euler', 'euler_again')
    assert block_support(params) == 'output euler_again has no block form'


def test_a_block_a_conversion_rejects_changes_nothing(monkeypatch):
    params = NodeParameters(input_type='imu', outputs=('euler', 'angular_velocity'),
                            angular_velocity_input_frame='world')
    pipeline = ConversionPipeline(params)
    blocks = BlockPipeline(pipeline)
    assert blocks.process_block(_block(10)) is not None
    state = (pipeline._previous_euler, pipeline.stats.received)

    def rejects(*args, **kwargs):
        raise ValueError('q: rejected')

    monkeypatch.setattr(conversions, 'rotate_vector', rejects)
    assert blocks.process_block(_block(10, seed=1)) is None
    assert (pipeline._previous_euler, pipeline.stats.received) == state


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.floats(-10.0, 10.0), st.sampled_from(
    [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, 180.0, -180.0, 540.0])), min_size=1,
    max_size=30), st.sampled_from([2.0 * math.pi, 360.0]), st.sampled_from([0.0, -0.0, 1.0]))
def test_unwrap_chain_is_the_pipelines_unwrapping(angles, period, start):
    first = np.array(angles)
    third = -first
    block_pipeline._unwrap_chain(first, third, start, -start, period)
    previous_first, previous_third = start, -start
    for k, angle in enumerate(angles):
        previous_first = _unwrapped(angle, previous_first, period)
        previous_third = _unwrapped(-angle, previous_third, period)
        assert np.float64(previous_first).tobytes() == first[k].tobytes()
        assert np.float64(previous_third).tobytes() == third[k].tobytes()


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([-1.0, -0.0, 0.0, 0.5, 2.0]), max_size=30))
def test_sign_chain_flips_as_the_pipeline_does(dots):
    """A quaternion flips when its dot product with the previous, flipped, one is negative."""
    signs = block_pipeline._sign_chain(np.array(dots, dtype=float))
    previous_sign = 1.0
    for k, dot in enumerate(dots):
        sign = -1.0 if previous_sign * dot < 0.0 else 1.0
        assert signs[k] == sign
        previous_sign = sign
