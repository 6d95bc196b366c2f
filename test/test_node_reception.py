"""Tests of rotation_node.node.reception: lost and duplicate messages from their message info."""
import itertools
import random

import pytest

from rotation_node.node.reception import MAX_PUBLISHERS, message_identity, Reception


def info(number, stamp=None, gid=None):
    """Return rclpy's message info of the message ``number`` of a publisher (GID: newer rclpy)."""
    message_info = {'publication_sequence_number': number,
                    'source_timestamp': 1_000 * number if stamp is None else stamp,
                    'received_timestamp': 0, 'reception_sequence_number': None}
    if gid is not None:
        message_info['publisher_gid'] = {'implementation_identifier': 'rmw_fastrtps_cpp',
                                         'data': gid.ljust(16, b'\0')}
    return message_info


def restarted_stream(gids=(None, None)):
    """
    Yield the issue's stream: A sends 1..100, leaves; B sends 1..50, loses 51..150, sends 151..200.

    Yields ``(publisher, info)``: 200 messages received of 300, 100 lost.
    """
    for n in range(1, 101):
        yield 'A', info(n, stamp=n, gid=gids[0])
    for n in [*range(1, 51), *range(151, 201)]:
        yield 'B', info(n, stamp=10**6 + n, gid=gids[1])


def test_gaps_in_one_publishers_numbers_are_counted_exactly():
    rng = random.Random(3)
    received = sorted(rng.sample(range(1, 10_001), 6_000))
    reception = Reception(100)
    assert all(reception.accept(info(n)) for n in received)
    # Before the first message nothing counts (a volatile subscription joins late).
    assert reception.lost == 10_000 - 6_000 - (received[0] - 1) - (10_000 - received[-1])
    assert reception.duplicates == 0


def test_a_message_seen_again_is_a_duplicate_and_not_a_gap():
    reception = Reception(10)
    for n in range(1, 8):
        assert reception.accept(info(n))
    assert reception.seen(info(5)) and not reception.seen(info(8))
    assert [reception.accept(info(n)) for n in (5, 6, 7, 8, 9)] == [
        False, False, False, True, True]
    assert (reception.lost, reception.duplicates) == (0, 3)


def test_memory_is_bounded():
    reception = Reception(3)
    for n in range(1, 6):
        reception.accept(info(n))
    assert not reception.seen(info(2)) and reception.seen(info(3))
    reception.resize(1)
    assert not reception.seen(info(4)) and reception.seen(info(5))


def test_same_number_from_another_publisher_is_not_a_duplicate():
    reception = Reception(10)
    assert reception.accept(info(1, stamp=100))
    assert reception.accept(info(1, stamp=101))
    assert reception.duplicates == 0


def test_interleaved_publishers_are_told_apart_by_continuity():
    """Two publishers far apart in numbering, one losing messages: only its gaps count."""
    reception = Reception(100)
    first = [n for n in range(5_000, 5_200) if n % 10 != 3]    # loses 20
    second = list(range(1, 201))                              # loses none
    for a, b in zip(first, second):
        reception.accept(info(a))
        reception.accept(info(b, stamp=7 + 1_000 * b))
    assert reception.lost == 20


def test_a_restarted_publisher_is_a_new_sequence():
    reception = Reception(100)
    for n in range(1, 101):
        reception.accept(info(n))
    for n in range(1, 51):   # numbers start again, with new source timestamps
        assert reception.accept(info(n, stamp=10**9 + n))
    assert reception.lost == 0


@pytest.mark.parametrize('gid', [None, b'A'], ids=['without_gids', 'with_gids'])
def test_a_message_older_than_one_accepted_stays_lost(gid):
    """
    Late messages are not accepted, and stay counted lost.

    A replaced subscription's successor delivers, from the publisher's history, messages
    the old one skipped, after newer ones (seen under load, qos.depth changed mid-stream).
    """
    reception = Reception(100)
    assert all(reception.accept(info(n, gid=gid)) for n in [*range(1, 11), *range(20, 26)])
    assert reception.lost == 9
    assert not any(reception.accept(info(n, gid=gid)) for n in range(11, 16))   # late
    assert reception.accept(info(26, gid=gid)) and not reception.accept(info(22, gid=gid))
    assert (reception.lost, reception.duplicates, reception.publishers) == (9, 1, 1)
    assert all(reception.accept(info(n, gid=gid)) for n in range(27, 30))
    assert reception.lost == 9


def test_publishers_followed_are_bounded():
    reception = Reception(1000)
    for publisher in range(MAX_PUBLISHERS + 3):
        reception.accept(info(1, stamp=publisher))
    assert reception.publishers == MAX_PUBLISHERS


def test_with_publisher_gids_a_restarted_publishers_loss_is_exact():
    reception = Reception(100)
    assert all(reception.accept(i) for _, i in restarted_stream((b'A', b'B')))
    assert (reception.lost, reception.duplicates) == (100, 0)


def test_with_publisher_gids_interleaved_publishers_are_exact():
    """Numbers close together, so that continuity alone would mix them up."""
    reception = Reception(1000)
    first = [n for n in range(1, 301) if n % 10 != 3]     # loses 30
    second = [n for n in range(5, 305) if n % 50 != 0]    # loses 6
    for a, b in itertools.zip_longest(first, second):
        if a is not None:
            reception.accept(info(a, stamp=2 * a, gid=b'first'))
        reception.accept(info(b, stamp=2 * b + 1, gid=b'second'))
    assert reception.lost == 30 + 6


def test_without_gids_a_publisher_that_left_is_forgotten():
    """A new sequence asks for the matched publishers (one: B), so A's numbers are not B's."""
    matched = {'count': 1}
    reception = Reception(100, on_new_publisher=lambda: reception.retain(matched['count']))
    assert all(reception.accept(i) for _, i in restarted_stream())
    assert reception.lost == 100 and reception.publishers == 1


def test_without_gids_retain_from_time_to_time_forgets_publishers_that_left():
    """Told late (B started while A was still matched): the next retain fixes it."""
    reception = Reception(100)
    for publisher, message_info in restarted_stream():
        if publisher == 'B' and message_info['publication_sequence_number'] == 20:
            reception.retain(1)   # the periodic check: A no longer matched
        reception.accept(message_info)
    assert reception.lost == 100


def test_retain_keeps_the_publishers_heard_last():
    reception = Reception(100)
    for stamp, number in enumerate([500, 1, 501, 2, 3]):   # two sequences, 3 heard last
        reception.accept(info(number, stamp=stamp))
    assert (reception.lost, reception.publishers) == (0, 2)
    reception.retain(1)
    reception.accept(info(7, stamp=10))
    assert reception.lost == 3 and reception.publishers == 1
    reception.retain(0)
    assert reception.publishers == 0
    reception.accept(info(700, stamp=11))   # a sequence starts again: no gap
    assert reception.lost == 3


def test_a_new_sequence_is_reported():
    started = []
    reception = Reception(100, on_new_publisher=lambda: started.append(reception.publishers))
    for stamp, number in enumerate([1, 2, 3, 1, 4, 2]):
        reception.accept(info(number, stamp=stamp))
    assert started == [1, 2]


def test_without_sequence_numbers_nothing_is_counted_lost():
    reception = Reception(10)
    assert reception.accept({'publication_sequence_number': None, 'source_timestamp': 5})
    assert reception.accept({'publication_sequence_number': None, 'source_timestamp': 9})
    assert not reception.accept({'publication_sequence_number': None, 'source_timestamp': 5})
    assert reception.lost == 0


def test_forget_accepts_the_same_messages_again():
    reception = Reception(10)
    reception.accept(info(1))
    reception.forget()
    assert reception.accept(info(1))


def test_identity_is_number_and_source_stamp():
    assert message_identity(info(4, stamp=17)) == (4, 17)


@pytest.mark.parametrize('memory', [0, -1])
def test_memory_must_be_positive(memory):
    with pytest.raises(ValueError, match='memory'):
        Reception(memory)
