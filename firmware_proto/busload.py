"""Worst-case bus load of the protocol's periodic frames, computed from ``hexapod.dbc``.

Frame lengths, frame formats (classic or FD, bit-rate switch), cycle times and profile
membership all come from the DBC; PROTOCOL.md's bus-load section is :func:`render_markdown`'s
output (``python -m firmware_proto.generate`` rewrites it, a test checks it).

Counting rules, all with 11-bit identifiers:

* Classic frame of n data bytes: 47 + 8n bits of frame incl. 3-bit intermission, plus worst-case
  stuff bits floor((34 + 8n - 1) / 4) over SOF..CRC: ``55 + 10n`` bits.
* CAN FD frame of n data bytes (ISO 11898-1:2015), split by phase:
  nominal phase: SOF, 11-bit id, RRS, IDE, FDF, res, BRS (17 bits) with at most 4 stuff bits,
  then CRC delimiter, ACK slot, ACK delimiter, 7-bit EOF and 3-bit intermission (13 bits): 34 bits;
  data phase: ESI and 4-bit DLC, 8n data bits, ceil((5 + 8n) / 4) dynamic stuff bits, 4-bit stuff
  count, 17-bit (n <= 16) or 21-bit CRC and their 6 or 7 fixed stuff bits.
  Charging the CRC delimiter at the nominal rate and rounding the stuff bits up makes this an
  upper bound. Without bit-rate switch the data phase runs at the nominal rate.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cantools.database.can import Database, Message

LOOP_RATES_HZ = (250, 500, 1000)
DEFAULT_LOOP_RATE_HZ = 500
BUS_LOAD_LIMIT = 0.60
"""Worst-case load a configuration may use; the rest absorbs event frames, retransmissions and jitter."""


@dataclass(frozen=True)
class BitRate:
    """Bus bit timing: the nominal (arbitration) rate and, on a CAN FD bus, the data-phase rate."""

    nominal_bps: int
    data_bps: int | None = None

    @property
    def label(self) -> str:
        nominal = _format_bps(self.nominal_bps)
        return nominal if self.data_bps is None else f"{nominal} / {_format_bps(self.data_bps)}"


CLASSIC_500K = BitRate(500_000)
CLASSIC_1M = BitRate(1_000_000)
FD_500K_2M = BitRate(500_000, 2_000_000)
FD_1M_5M = BitRate(1_000_000, 5_000_000)


class Profile(Enum):
    """Bus profiles; the value is the DBC ``BusProfile`` choice that only this profile carries."""

    CLASSIC = "ClassicOnly"
    FD = "FDOnly"

    @property
    def bit_rates(self) -> tuple[BitRate, ...]:
        return (CLASSIC_500K, CLASSIC_1M) if self is Profile.CLASSIC else (FD_500K_2M, FD_1M_5M)


_BOTH_PROFILES = "ClassicAndFD"


def classic_frame_bits(length: int) -> int:
    """Worst-case bits of a classic frame with ``length`` data bytes, bit stuffing included."""
    return 55 + 10 * length


def fd_frame_bits(length: int) -> tuple[int, int]:
    """Worst-case ``(nominal_phase_bits, data_phase_bits)`` of a CAN FD frame with ``length`` bytes."""
    nominal = 17 + 4 + 13
    dynamic = 5 + 8 * length
    crc_bits, fixed_stuff_bits = (17, 6) if length <= 16 else (21, 7)
    data = dynamic + -(-dynamic // 4) + 4 + crc_bits + fixed_stuff_bits
    return nominal, data


def _enum_attribute(db: Database, message: Message, name: str) -> str:
    definition = db.dbc.attribute_definitions[name]
    attribute = message.dbc.attributes.get(name)
    return definition.default_value if attribute is None else definition.choices[attribute.value]


def frame_time_s(db: Database, message: Message, bit_rate: BitRate) -> float:
    """Worst-case bus time of one ``message`` frame in seconds.

    :raises ValueError: for an FD frame on a classic bit rate
    """
    if not message.is_fd:
        return classic_frame_bits(message.length) / bit_rate.nominal_bps
    if bit_rate.data_bps is None:
        raise ValueError(f"{message.name} is a CAN FD frame; {bit_rate.label} is a classic bit rate")
    nominal_bits, data_bits = fd_frame_bits(message.length)
    switches = _enum_attribute(db, message, "CANFD_BRS") == "1"
    return nominal_bits / bit_rate.nominal_bps + data_bits / (bit_rate.data_bps if switches else bit_rate.nominal_bps)


def follows_loop_rate(db: Database, message: Message) -> bool:
    """Whether ``message`` goes once per loop cycle (DBC ``CycleTimeFollowsLoopRate``).

    Such a message's ``GenMsgCycleTime`` is the default loop period.
    """
    return _enum_attribute(db, message, "CycleTimeFollowsLoopRate") == "Yes"


def message_rate_hz(db: Database, message: Message, loop_rate_hz: float) -> float:
    """Frames per second of a periodic ``message`` when the control loop runs at ``loop_rate_hz``."""
    if follows_loop_rate(db, message):
        return loop_rate_hz
    return 1000 / message.cycle_time


def periodic_messages(db: Database, profile: Profile) -> list[Message]:
    """The messages with a cycle time that ``profile`` puts on the bus, by identifier."""
    carried = {_BOTH_PROFILES, profile.value}
    return sorted(
        (m for m in db.messages if m.cycle_time and _enum_attribute(db, m, "BusProfile") in carried),
        key=lambda m: m.frame_id,
    )


@dataclass(frozen=True)
class FrameLoad:
    message: Message
    rate_hz: float
    load: float
    """Fraction of the bus time."""


def frame_loads(db: Database, profile: Profile, loop_rate_hz: float, bit_rate: BitRate) -> list[FrameLoad]:
    """Worst-case load of every periodic frame of ``profile``."""
    loads = []
    for message in periodic_messages(db, profile):
        rate_hz = message_rate_hz(db, message, loop_rate_hz)
        loads.append(FrameLoad(message, rate_hz, rate_hz * frame_time_s(db, message, bit_rate)))
    return loads


def bus_load(db: Database, profile: Profile, loop_rate_hz: float, bit_rate: BitRate) -> float:
    """Worst-case fraction of the bus time used by ``profile``'s periodic frames."""
    return sum(frame.load for frame in frame_loads(db, profile, loop_rate_hz, bit_rate))


def _format_bps(bps: int) -> str:
    return f"{bps // 1_000_000} Mbit/s" if bps % 1_000_000 == 0 else f"{bps // 1000} kbit/s"


def _percent(load: float, digits: int) -> str:
    return f"{100 * load:.{digits}f} %"


def _verdict(load: float) -> str:
    return f"{_percent(load, 1)} {'ok' if load <= BUS_LOAD_LIMIT else 'OVER'}"


def _worst_case_length(message: Message) -> str:
    if message.is_fd:
        nominal, data = fd_frame_bits(message.length)
        return f"{nominal} + {data} bit"
    return f"{classic_frame_bits(message.length)} bit"


def _frame_row(same_frame: Iterable[FrameLoad]) -> list[str]:
    """Table row of one message at each loop rate."""
    loads = list(same_frame)
    message = loads[0].message
    return [message.name, f"0x{message.frame_id:03X}", str(message.length), _worst_case_length(message)] + [
        f"{frame.rate_hz:g} Hz: {_percent(frame.load, 2)}" for frame in loads
    ]


def _table(header: Iterable[str], rows: Iterable[Iterable[str]]) -> list[str]:
    header = list(header)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def render_markdown(db: Database) -> str:
    """The bus-load section of PROTOCOL.md: a summary, then every periodic frame per profile and bit rate."""
    loop_columns = [f"{rate} Hz loop" for rate in LOOP_RATES_HZ]
    limit = _percent(BUS_LOAD_LIMIT, 0)
    lines = [
        f"Worst-case load of the periodic frames ('ok' means at most {limit}). "
        f"Default: classic profile, {DEFAULT_LOOP_RATE_HZ} Hz loop, {CLASSIC_1M.label}.",
        "",
    ]
    summary = [
        [profile.name, bit_rate.label] + [_verdict(bus_load(db, profile, rate, bit_rate)) for rate in LOOP_RATES_HZ]
        for profile in Profile
        for bit_rate in profile.bit_rates
    ]
    lines += _table(["Profile", "Bit rate"] + loop_columns, summary)
    for profile in Profile:
        for bit_rate in profile.bit_rates:
            per_rate = [frame_loads(db, profile, rate, bit_rate) for rate in LOOP_RATES_HZ]
            rows = [_frame_row(same_frame) for same_frame in zip(*per_rate)]
            totals = [f"**{_verdict(sum(frame.load for frame in loads))}**" for loads in per_rate]
            rows.append(["**Total**", "", "", ""] + totals)
            lines += ["", f"**{profile.name} profile, {bit_rate.label}**", ""]
            lines += _table(["Frame", "ID", "Bytes", "Worst case"] + loop_columns, rows)
    return "\n".join(lines) + "\n"
