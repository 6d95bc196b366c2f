"""Tests of rotation_node.reception: lost and duplicate messages from their message info."""
import random

import pytest

from rotation_node.reception import MAX_PUBLISHERS, message_identity, Reception


def info(number, stamp=None):
    """Return rclpy's message info of the message ``number`` of a publisher."""
    return {'publication_sequence_number': number,
            'source_timestamp': 1_000 * number if stamp is None else stamp,
            'received_timestamp': 0, 'reception_sequence_number': None}


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


def test_publishers_followed_are_bounded():
    reception = Reception(1000)
    for publisher in range(MAX_PUBLISHERS + 3):
        reception.accept(info(1, stamp=publisher))
    assert len(reception._last_numbers) == MAX_PUBLISHERS


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
