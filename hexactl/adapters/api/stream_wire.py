"""A pose stream's samples on the wire: one binary layout, and a text line for simulator software.

Both travel one sample per message: a ZeroMQ message on the stream socket, or a UDP
datagram on the stream port (docs/stream.md).

**Binary** (64 bytes, little-endian; what hexactl's own sender uses)::

    offset  size  type      field
    0       4     bytes     magic b"HXS1"
    4       4     uint32    sequence: increases by at least 1 from sample to sample
    8       8     float64   sent_s: the sender's clock when it sent the sample, s
    16      48    6×float64 x, y, z (mm), roll, pitch, yaw (deg), in the stream's frame

Why binary: fixed size, exact doubles, decoded with one ``struct.unpack`` (no parsing
at 1 kHz); why these fields: the sequence number drops reordered and duplicated
datagrams, and the sender's time gives the stream's velocity without the jitter of the
network.

**Text** (ASCII, what motion-simulator software can be set up to emit: FlyPT Mover's
and SimTools' UDP outputs send a line built from a template): 8 numbers, ``sequence
sent_s x y z roll pitch yaw``, or 6, ``x y z roll pitch yaw`` (then the receiver numbers
them after the last sample taken and stamps them on arrival: reordering cannot be
detected), separated by spaces, commas or semicolons, an optional line end. Each number is
written as a decimal (``-12``, ``0.5``, ``1e-3``); Python's other spellings (``1_0``,
``inf``) are refused.

``sent_s`` is a time in seconds of the sender's clock (its origin is the sender's):
within ±:data:`MAX_SENT_S`.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from math import isfinite

from hexactl.kinematics.axes import POSE_MAGNITUDE_LIMIT
from hexactl.kinematics.plain_numbers import PLAIN_DECIMAL

MAGIC = b"HXS1"
BINARY = struct.Struct("<4sId6d")

LAST_SEQUENCE = 2**32 - 1
"""The largest sequence a sample carries (uint32)."""
MAX_TEXT_BYTES = 512
MAX_SENT_S = 1e12
"""The largest sender's time, s (31 700 years): any clock a sender keeps, and far from where
a time in nanoseconds would overflow."""
_SEPARATORS = re.compile(r"[\s,;]+")


class MalformedSample(ValueError):
    """A message that is not a sample; the message says what is wrong with it."""


@dataclass(frozen=True, slots=True)
class Sample:
    """A decoded sample: ``sequence`` and ``sent_s`` None for a 6-number text line."""

    sequence: int | None
    sent_s: float | None
    pose: tuple[float, float, float, float, float, float]


def encode(sequence: int, sent_s: float, pose: tuple[float, ...] | list[float]) -> bytes:
    """The binary form of a sample (pose mm and deg).

    :raises struct.error: a sequence outside uint32 or not six pose values
    """
    return BINARY.pack(MAGIC, sequence, sent_s, *pose)


def decode(message: bytes) -> Sample:
    """The sample in ``message`` (binary or text).

    :raises MalformedSample: naming what is wrong
    """
    if message[:4] == MAGIC:
        if len(message) != BINARY.size:
            raise MalformedSample(f"a binary sample is {BINARY.size} bytes, this one {len(message)}")
        _, sequence, sent_s, *pose = BINARY.unpack(message)
        if _big_endian(message, (sent_s, *pose)):
            raise MalformedSample(f"the numbers are big-endian (network byte order): a binary sample's are "
                                  f"little-endian (struct format {BINARY.format!r})")
        return _checked(sequence, sent_s, pose)
    if len(message) > MAX_TEXT_BYTES:
        raise MalformedSample(f"neither a binary sample (magic {MAGIC!r}) nor a text line of at most "
                              f"{MAX_TEXT_BYTES} bytes ({len(message)} bytes)")
    try:
        fields = [field for field in _SEPARATORS.split(message.decode("ascii").strip()) if field]
    except UnicodeDecodeError:
        fields = []
    if not fields or not all(PLAIN_DECIMAL.fullmatch(field) for field in fields):
        raise MalformedSample("neither a binary sample (magic b'HXS1') nor a text line of decimal numbers")
    values = [float(field) for field in fields]
    if len(values) == 6:
        return _checked(None, None, values)
    if len(values) == 8:
        sequence = values[0]
        if not sequence.is_integer() or not 0 <= sequence <= LAST_SEQUENCE:
            raise MalformedSample(f"a sample's sequence is a whole number in [0, 2³²), got {fields[0]}")
        return _checked(int(sequence), values[1], values[2:])
    raise MalformedSample(f"a text sample is 8 numbers (sequence, sent_s, x, y, z, roll, pitch, yaw) or 6 (the "
                          f"pose), got {len(values)}")


_SWAPPED = struct.Struct(">" + BINARY.format[1:])

_SMALLEST_PLAUSIBLE = 1e-9
"""Below this (mm, deg, s), but not zero, no sender means a value: a double's bytes in the
other order read as one of about 3 % of the exponents between this and the largest bound."""


def _big_endian(message: bytes, numbers: tuple[float, ...]) -> bool:
    """Whether a binary sample's ``numbers`` (sent_s and pose, read little-endian) hold
    values a sender cannot mean, and fewer of them read big-endian, none beyond its bound.
    Found from outside: half of a big-endian sender's samples were taken, their poses about
    1e-317 (the zero posture, where the platform went); a first rule that looked at
    subnormals only let poses of about 1e-236 through, and refused a little-endian sample
    holding a subnormal."""
    unmeant = _unmeant(numbers)
    if not unmeant:
        return False
    _, _, *swapped = _SWAPPED.unpack(message)
    swapped_unmeant = _unmeant(tuple(swapped))
    return len(swapped_unmeant) < len(unmeant) and not any(abs(value) >= _SMALLEST_PLAUSIBLE
                                                            for value in swapped_unmeant)


def _unmeant(numbers: tuple[float, ...]) -> list[float]:
    """Those of sent_s and the pose that are neither 0 nor within what a sender means."""
    sent_s, *pose = numbers
    return [value for value, high in ((sent_s, MAX_SENT_S), *((value, POSE_MAGNITUDE_LIMIT) for value in pose))
            if value != 0.0 and not (isfinite(value) and _SMALLEST_PLAUSIBLE <= abs(value) <= high)]


def _checked(sequence: int | None, sent_s: float | None, pose: list[float]) -> Sample:
    if sent_s is not None and not (isfinite(sent_s) and abs(sent_s) <= MAX_SENT_S):
        raise MalformedSample(f"a sample's sent_s is a time in s within ±{MAX_SENT_S:g}, got {sent_s}")
    for value in pose:
        if not isfinite(value) or abs(value) > POSE_MAGNITUDE_LIMIT:
            raise MalformedSample(f"a sample's pose is six finite numbers (mm, deg) within ±{POSE_MAGNITUDE_LIMIT:g}, "
                                  f"got {value}")
    return Sample(sequence, sent_s, tuple(pose))  # type: ignore[arg-type]
