"""
Time stamps: ROS ``builtin_interfaces/Time`` <-> integer nanoseconds <-> seconds text.

Stamps are compared and subtracted as integer nanoseconds: a float of seconds since 1970
keeps only ~0.2 us.
"""
from typing import Any, Tuple

NS_PER_S = 1_000_000_000


def stamp_ns(stamp: Any) -> int:
    """Return a ``builtin_interfaces/Time`` (or anything with ``sec``, ``nanosec``) in ns."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def header_stamp_ns(header: Any) -> int:
    """Return the stamp of a std_msgs/Header (or a view of one) in integer nanoseconds."""
    stamp = header.stamp
    return stamp.sec * NS_PER_S + stamp.nanosec


def split_ns(nanoseconds: int) -> Tuple[int, int]:
    """Return ``(sec, nanosec)`` of a time in ns, ``nanosec`` in [0, 1e9) (as ROS stores it)."""
    return divmod(int(nanoseconds), NS_PER_S)


def time_message(nanoseconds: int) -> Any:
    """Return a builtin_interfaces/Time holding ``nanoseconds``."""
    from builtin_interfaces.msg import Time   # here: the module does not import rclpy
    seconds, rest = split_ns(nanoseconds)
    return Time(sec=seconds, nanosec=rest)


def seconds_text(nanoseconds: int) -> str:
    """Return a time in ns as exact seconds text: ``'12.000000500'``, -1 ns ``'-1.999999999'``."""
    seconds, rest = split_ns(nanoseconds)
    return f'{seconds}.{rest:09d}'
