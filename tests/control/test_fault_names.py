"""Fault words named for people: :class:`FaultNames` from a protocol's flag type, and
:func:`fault_text`, the form every message uses."""

from __future__ import annotations

from enum import IntFlag

import pytest

from hexactl.control.hardware import FaultNames, fault_text


class Bits(IntFlag):
    """A protocol with bits 0, 1 and 3 defined (2 is not)."""

    COMM_TIMEOUT = 1 << 0
    LIMIT_SWITCH = 1 << 1
    SENSOR = 1 << 3


NAMES = FaultNames(Bits)


def test_each_set_bit_is_named_lowest_first_in_the_protocols_spelling_lower_cased():
    assert NAMES(0) == ()
    assert NAMES(Bits.SENSOR) == ("sensor",)
    assert NAMES(Bits.SENSOR | Bits.COMM_TIMEOUT | Bits.LIMIT_SWITCH) == ("comm_timeout", "limit_switch", "sensor")


def test_a_bit_the_protocol_does_not_define_is_named_by_its_number_not_dropped():
    assert NAMES(1 << 2) == ("bit_2",)
    assert NAMES(1 << 13 | Bits.SENSOR | 1 << 2) == ("bit_2", "sensor", "bit_13")
    assert NAMES(1 << 70) == ("bit_70",)


def test_a_word_is_named_the_same_every_time_and_a_negative_one_is_refused():
    assert NAMES(0x9) is NAMES(0x9)  # named once: the implementations ask on every read
    with pytest.raises(ValueError, match="not negative"):
        NAMES(-1)


def test_fault_text_gives_the_names_and_the_word():
    assert fault_text(("comm_timeout", "sensor"), 0x9) == "comm_timeout, sensor (0x9)"
    assert fault_text(NAMES(0x2004), 0x2004) == "bit_2, bit_13 (0x2004)"
    assert fault_text((), 0) == "none"
