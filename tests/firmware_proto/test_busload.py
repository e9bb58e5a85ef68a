"""The bus-load budget: formulas, PROTOCOL.md's tables, and the limits it promises."""

import pytest

from firmware_proto import busload
from firmware_proto.busload import CLASSIC_1M, FD_1M_5M, Profile, bus_load
from firmware_proto.generate import BUS_LOAD_BEGIN, PROTOCOL_MD, render_protocol_md

from .frames import DB


@pytest.mark.parametrize("length", range(9))
def test_classic_frame_worst_case_is_55_plus_10_bits_per_byte(length):
    frame_bits = 47 + 8 * length
    stuffed_region = 34 + 8 * length
    assert busload.classic_frame_bits(length) == frame_bits + (stuffed_region - 1) // 4 == 55 + 10 * length


def test_fd_frame_worst_case():
    assert busload.fd_frame_bits(8) == (34, 5 + 64 + 18 + 4 + 17 + 6)
    assert busload.fd_frame_bits(20) == (34, 5 + 160 + 42 + 4 + 21 + 7)


def test_protocol_md_tables_are_the_computed_ones():
    text = PROTOCOL_MD.read_text(encoding="utf-8")
    assert render_protocol_md(DB, text) == text, "run python -m firmware_proto.generate"
    assert busload.render_markdown(DB) in text


def test_default_configuration_fits_within_the_limit():
    assert bus_load(DB, Profile.CLASSIC, busload.DEFAULT_LOOP_RATE_HZ, CLASSIC_1M) <= busload.BUS_LOAD_LIMIT


def test_default_load_by_hand():
    setpoint_cycle = 3 * busload.classic_frame_bits(8) + busload.classic_frame_bits(2)
    bits_per_s = setpoint_cycle * 500 + 6 * busload.classic_frame_bits(8) * 250 + 6 * busload.classic_frame_bits(4) * 10
    assert bus_load(DB, Profile.CLASSIC, 500, CLASSIC_1M) == pytest.approx(bits_per_s / 1e6)


def test_default_streams_feedback_at_250_hz_and_heartbeats_from_every_actuator():
    loads = {f.message.name: f.rate_hz for f in busload.frame_loads(DB, Profile.CLASSIC, 500, CLASSIC_1M)}
    for node in range(1, 7):
        assert loads[f"FEEDBACK_{node}"] >= 250
        assert loads[f"HEARTBEAT_{node}"] == 10


def test_one_khz_needs_the_fd_profile():
    assert bus_load(DB, Profile.CLASSIC, 1000, CLASSIC_1M) > busload.BUS_LOAD_LIMIT
    assert bus_load(DB, Profile.FD, 1000, FD_1M_5M) <= busload.BUS_LOAD_LIMIT


def test_profiles_carry_their_own_set_point_path():
    classic = {m.name for m in busload.periodic_messages(DB, Profile.CLASSIC)}
    fd = {m.name for m in busload.periodic_messages(DB, Profile.FD)}
    shared = {f"{kind}_{n}" for kind in ("FEEDBACK", "HEARTBEAT") for n in range(1, 7)}
    assert classic == shared | {"SETPOINT_12", "SETPOINT_34", "SETPOINT_56", "SYNC"}
    assert fd == shared | {"SETPOINT_ALL_FD"}


def test_an_fd_frame_needs_an_fd_bit_rate():
    with pytest.raises(ValueError):
        busload.frame_time_s(DB, DB.get_message_by_name("SETPOINT_ALL_FD"), CLASSIC_1M)


def test_protocol_md_prose_quotes_the_computed_figures():
    prose = PROTOCOL_MD.read_text(encoding="utf-8").split(BUS_LOAD_BEGIN)[0]
    for profile, loop_rate_hz, bit_rate in [
        (Profile.CLASSIC, 500, CLASSIC_1M),
        (Profile.CLASSIC, 1000, CLASSIC_1M),
        (Profile.FD, 1000, FD_1M_5M),
    ]:
        assert f"{100 * bus_load(DB, profile, loop_rate_hz, bit_rate):.1f} %" in prose
