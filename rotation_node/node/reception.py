"""
What one input topic of the node has received: lost messages and duplicates.

Every message a ROS 2 subscription takes comes with its message info, which
(with rmw_fastrtps) holds the publication sequence number that the publisher
gave it (1, 2, 3, ... per publisher) and the publisher's source timestamp.
:class:`Reception` uses them for two things:

- **loss**: a jump in a publisher's sequence numbers is messages that this
  subscription never got, wherever they were lost (on the wire, in the
  publisher's or the subscription's history); the rmw's message-lost events
  see only some of them;
- **duplicates**: while the node replaces a subscription (a new QoS), the old
  and the new one both receive the same messages for a moment; a message
  already accepted is recognised by its (sequence number, source timestamp).
  The new one can also deliver, from the publisher's history, messages older
  than the last one accepted from that publisher, which the old one skipped:
  they were counted lost in its gap, and are not accepted (late).

Which publisher sent a message: newer rclpy releases put the publisher's GID in
the message info (``publisher_gid``) and gaps are then counted per publisher,
exactly. Jazzy's rclpy does not; the sequence numbers are then told apart by
continuity: each number is assigned to the publisher whose last number is the
closest below it, a number with none below starts a new publisher (one that
restarted or joined), and the sequences of publishers that left are forgotten
(:meth:`Reception.retain`, with the subscription's count of matched
publishers): a publisher that comes back or a new one is never credited with
the numbers of one that went. Exact for one publisher at a time, however often
it restarts; an estimate with several at once. This module does not import
rclpy.
"""
import collections
from typing import Any, Callable, Deque, List, Mapping, Optional, Set, Tuple

#: Publishers (sequences of publication numbers) followed per topic; a new one
#: beyond this replaces the one heard from least recently.
MAX_PUBLISHERS = 8

Identity = Tuple[Optional[int], Optional[int]]


def message_identity(info: Mapping[str, Any]) -> Identity:
    """Return ``(publication sequence number, source timestamp)`` of a message info."""
    return info.get('publication_sequence_number'), info.get('source_timestamp')


def publisher_key(info: Mapping[str, Any]) -> Optional[bytes]:
    """Return the publisher's GID bytes of a message info, or None where rclpy gives none."""
    gid = info.get('publisher_gid')
    if gid is None:
        return None
    if isinstance(gid, Mapping):   # rclpy: {'implementation_identifier': ..., 'data': bytes}
        gid = gid.get('data')
    return None if gid is None else bytes(gid)


class Reception:
    """
    Lost and duplicate messages of one input topic, from their message info.

    Parameters
    ----------
    memory : int
        How many recent messages are remembered to recognise duplicates: at
        least the history depth of the subscriptions (a new subscription can be
        handed as many already-delivered messages as the publisher keeps).
    on_new_publisher : callable, optional
        Called (no arguments) when a message starts a new sequence: a publisher
        joined or restarted, and one may have left (see :meth:`retain`).

    Attributes
    ----------
    lost : int
        Messages skipped in the publishers' sequence numbers.
    duplicates : int
        Messages received a second time (and not accepted).

    """

    def __init__(self, memory: int, on_new_publisher: Optional[Callable[[], None]] = None):
        self.lost = 0
        self.duplicates = 0
        self._seen: Set[Identity] = set()
        self._order: Deque[Identity] = collections.deque()   # of _seen, oldest first
        # per publisher [GID or None, last number, its source timestamp], the most recently
        # heard first
        self._sequences: List[list] = []
        self._on_new_publisher = on_new_publisher
        self.resize(memory)

    @property
    def publishers(self) -> int:
        """Count the sequences of publication numbers (publishers) followed now."""
        return len(self._sequences)

    def seen(self, info: Mapping[str, Any]) -> bool:
        """Whether the message of ``info`` was accepted already (and is remembered)."""
        return message_identity(info) in self._seen

    def accept(self, info: Mapping[str, Any]) -> bool:
        """
        Return whether a message is new; count it, and any gap before it.

        Parameters
        ----------
        info : mapping
            rclpy's message info (``publication_sequence_number``,
            ``source_timestamp``, ``publisher_gid`` where rclpy gives it); a
            missing or None sequence number counts no gap.

        """
        identity = message_identity(info)
        seen = self._seen
        if identity in seen:
            self.duplicates += 1
            return False
        seen.add(identity)
        order = self._order
        order.append(identity)
        if len(order) > self._memory:
            seen.discard(order.popleft())
        number, stamp = identity
        if number is not None:
            key = publisher_key(info)
            if self._late(number, stamp, key):
                return False
            self.lost += self._gap(number, key, stamp)
        return True

    def _late(self, number: int, stamp: Optional[int], key: Optional[bytes]) -> bool:
        """
        Whether a message is older than one already accepted from its publisher.

        Counted lost in that publisher's gap already; accepting it would count it twice
        (and convert it out of order). Its publisher: the one of its GID; without GIDs,
        a sequence past its number, whose last message was sent later, within the
        messages remembered (a restarted publisher's messages are sent later than all
        before, a publisher far behind another is another).
        """
        for sequence_key, last, last_stamp in self._sequences:
            if sequence_key == key and number < last and (
                    key is not None
                    or (stamp is not None and last_stamp is not None and stamp < last_stamp
                        and last - number <= self._memory)):
                return True
        return False

    def _gap(self, number: int, key: Optional[bytes], stamp: Optional[int]) -> int:
        """Messages missing before ``number`` in the sequence it continues."""
        sequences = self._sequences
        if sequences:
            first = sequences[0]
            # the one publisher heard last, in order: the common case, first
            if first[0] == key and first[1] < number and (key is not None or len(sequences) == 1):
                gap = number - first[1] - 1
                first[1:] = number, stamp
                return gap
        if key is not None:   # the publisher is known: its own sequence, exactly
            for k, sequence in enumerate(sequences):
                if sequence[0] == key:
                    gap = max(number - sequence[1] - 1, 0)
                    if number > sequence[1]:
                        sequence[1:] = number, stamp
                    sequences.insert(0, sequences.pop(k))
                    return gap
            return self._new_sequence(key, number, stamp)
        below = [(sequence[1], k) for k, sequence in enumerate(sequences)
                 if sequence[0] is None and sequence[1] < number]
        if not below:   # a new publisher (or one that restarted)
            return self._new_sequence(None, number, stamp)
        last, k = max(below)
        sequence = sequences.pop(k)
        sequence[1:] = number, stamp
        sequences.insert(0, sequence)
        return number - last - 1

    def _new_sequence(self, key: Optional[bytes], number: int, stamp: Optional[int]) -> int:
        """Follow a publisher from its message ``number``; nothing before it counts."""
        self._sequences.insert(0, [key, number, stamp])
        del self._sequences[MAX_PUBLISHERS:]
        if self._on_new_publisher is not None:
            self._on_new_publisher()
        return 0

    def retain(self, publishers: int) -> None:
        """
        Forget the sequences of publishers that left: keep the ``publishers`` heard last.

        Call it with the number of publishers the subscription matches now (when
        it changes, or from time to time): those that left are the ones not heard
        from since, and a later publisher's gap is never credited to them.
        """
        del self._sequences[max(publishers, 0):]

    def resize(self, memory: int) -> None:
        """Remember ``memory`` recent messages from now on (see the class)."""
        if memory < 1:
            raise ValueError(f'memory must be at least 1, got {memory!r}')
        self._memory = memory
        while len(self._order) > memory:
            self._seen.discard(self._order.popleft())

    def forget(self) -> None:
        """Forget the accepted messages (a new input stream accepts them again)."""
        self._seen.clear()
        self._order.clear()
        self._sequences.clear()
