"""
What one input topic of the node has received: lost messages and duplicates.

From the publication sequence number and source timestamp of each message's
info (rmw_fastrtps): a jump in a publisher's numbers is messages lost wherever
they were; a message already accepted (while two subscriptions overlap, or
older than the last one accepted from its publisher) is not accepted again.
Without the publisher's GID (Jazzy's rclpy) each number continues the sequence
whose last number is closest below it, a number with none below starts a new
publisher, and the sequences of publishers that left are forgotten
(:meth:`Reception.retain`): exact for one publisher at a time, however often it
restarts. docs/node.md ("Lost messages") has the details. No rclpy import.
"""
import collections
from typing import Any, Callable, Deque, List, Mapping, Optional, Set, Tuple

MAX_PUBLISHERS = 8   # sequences followed per topic; beyond, the least recently heard goes

Identity = Tuple[Optional[int], Optional[int]]


def message_identity(info: Mapping[str, Any]) -> Identity:
    """Return ``(publication sequence number, source timestamp)`` of a message info."""
    return info.get('publication_sequence_number'), info.get('source_timestamp')


def _publisher_key(info: Mapping[str, Any]) -> Optional[bytes]:
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

    ``memory``: recent messages remembered, at least the subscriptions' depth (a
    new subscription may be handed that many again). ``on_new_publisher()``: a
    message started a new sequence (a publisher joined or restarted).
    """

    def __init__(self, memory: int, on_new_publisher: Optional[Callable[[], None]] = None):
        self.lost = 0         # messages skipped in the publishers' sequence numbers
        self.duplicates = 0   # messages received again (not accepted)
        self._seen: Set[Identity] = set()
        self._order: Deque[Identity] = collections.deque()   # of _seen, oldest first
        # per publisher [GID or None, last number, its source timestamp], last heard first
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
        """Return whether the message of an rclpy message info is new; count it, and any gap."""
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
            key = _publisher_key(info)
            if self._late(number, stamp, key):
                return False
            self.lost += self._gap(number, key, stamp)
        return True

    def _late(self, number: int, stamp: Optional[int], key: Optional[bytes]) -> bool:
        """
        Whether a message is older than one accepted from its publisher (counted lost already).

        Without GIDs its publisher is a sequence past its number whose last message
        was sent later, within the messages remembered.
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
        """Forget the sequences of publishers that left: keep the ``publishers`` heard last."""
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
