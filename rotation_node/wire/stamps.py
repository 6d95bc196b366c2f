"""
Time stamps: ROS ``builtin_interfaces/Time`` <-> integer nanoseconds <-> seconds text.

Stamps are handled as integer nanoseconds wherever they are compared or
subtracted: a float of seconds since 1970 keeps only ~0.2 us. This module
does not import rclpy; :func:`time_message` imports the message class when
called.
"""
from typing import Any, Tuple

NS_PER_S = 1_000_000_000
"""Nanoseconds per second."""


def stamp_ns(stamp: Any) -> int:
    """
    Return a stamp in integer nanoseconds.

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time or any object with ``sec`` and ``nanosec``
        The stamp.

    Returns
    -------
    int

    """
    return stamp.sec * NS_PER_S + stamp.nanosec


def header_stamp_ns(header: Any) -> int:
    """Return the stamp of a std_msgs/Header (or a view of one) in integer nanoseconds."""
    stamp = header.stamp
    return stamp.sec * NS_PER_S + stamp.nanosec


def split_ns(nanoseconds: int) -> Tuple[int, int]:
    """
    Return ``(sec, nanosec)`` of a time in integer nanoseconds, ``nanosec`` in [0, 1e9).

    Negative times give a negative ``sec`` and a non-negative ``nanosec``, as ROS
    stores them.
    """
    return divmod(int(nanoseconds), NS_PER_S)


def time_message(nanoseconds: int) -> Any:
    """Return a builtin_interfaces/Time holding ``nanoseconds``."""
    from builtin_interfaces.msg import Time
    seconds, rest = split_ns(nanoseconds)
    return Time(sec=seconds, nanosec=rest)


def seconds_text(nanoseconds: int) -> str:
    """
    Return a time in integer nanoseconds as exact decimal seconds, e.g. ``'12.000000500'``.

    Parameters
    ----------
    nanoseconds : int
        The time.

    Returns
    -------
    str
        ``sec`` and ``nanosec`` of :func:`split_ns` joined with a point, nanoseconds
        to nine digits: exact, no rounding (-1 ns prints as ``'-1.999999999'``, as
        ROS stores it).

    """
    seconds, rest = split_ns(nanoseconds)
    return f'{seconds}.{rest:09d}'
