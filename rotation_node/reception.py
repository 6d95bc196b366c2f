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

Message info does not name the publisher, so with several publishers on one
topic the sequence numbers are told apart by continuity: each number is
assigned to the publisher whose last number is the closest below it. The loss
count is exact for one publisher per topic, an estimate with several. This
module does not import rclpy.
"""
import collections
from typing import Any, Deque, List, Mapping, Optional, Set, Tuple

#: Publishers (sequences of publication numbers) followed per topic; a new one
#: beyond this replaces the one heard from least recently.
MAX_PUBLISHERS = 8

Identity = Tuple[Optional[int], Optional[int]]


def message_identity(info: Mapping[str, Any]) -> Identity:
    """Return ``(publication sequence number, source timestamp)`` of a message info."""
    return info.get('publication_sequence_number'), info.get('source_timestamp')


class Reception:
    """
    Lost and duplicate messages of one input topic, from their message info.

    Parameters
    ----------
    memory : int
        How many recent messages are remembered to recognise duplicates: at
        least the history depth of the subscriptions (a new subscription can be
        handed as many already-delivered messages as the publisher keeps).

    Attributes
    ----------
    lost : int
        Messages skipped in the publishers' sequence numbers.
    duplicates : int
        Messages received a second time (and not accepted).

    """

    def __init__(self, memory: int):
        self.lost = 0
        self.duplicates = 0
        self._seen: Set[Identity] = set()
        self._order: Deque[Identity] = collections.deque()   # of _seen, oldest first
        self._last_numbers: List[int] = []   # per publisher, the most recently heard first
        self.resize(memory)

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
            ``source_timestamp``); a missing or None sequence number counts no gap.

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
        number = identity[0]
        if number is not None:
            self.lost += self._gap(number)
        return True

    def _gap(self, number: int) -> int:
        """Messages missing before ``number`` in the sequence it continues."""
        last_numbers = self._last_numbers
        if len(last_numbers) == 1 and last_numbers[0] < number:   # one publisher, in order
            gap = number - last_numbers[0] - 1
            last_numbers[0] = number
            return gap
        below = [(last, k) for k, last in enumerate(last_numbers) if last < number]
        if not below:   # a new publisher (or one that restarted)
            last_numbers.insert(0, number)
            del last_numbers[MAX_PUBLISHERS:]
            return 0
        last, k = max(below)
        del last_numbers[k]
        last_numbers.insert(0, number)
        return number - last - 1

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
        self._last_numbers.clear()
