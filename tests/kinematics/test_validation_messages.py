"""Where an unknown key is, the keys taken there (kinematics/validation_messages.py)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from hexactl.kinematics.validation_messages import accepted_keys, unknown_key_message


class _Inner(BaseModel):
    model_config = ConfigDict(extra="forbid")
    dwell: float = 0.0
    speed: float = 1.0


class _Other(BaseModel):
    model_config = ConfigDict(extra="forbid")
    rate: float = 0.0


class _Outer(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = ""
    waypoints: tuple[_Inner, ...] = Field((), alias="waypoint")
    either: _Inner | _Other | None = None


def test_the_keys_taken_are_followed_through_lists_and_aliases() -> None:
    assert accepted_keys(_Outer, ["nmae"]) == ("name", "waypoint", "either")
    assert accepted_keys(_Outer, ["waypoint", 0, "dwel"]) == ("dwell", "speed")
    assert unknown_key_message("dwel", ("dwell", "speed")) == \
        "not a key here; did you mean dwell? the keys here are dwell, speed"


def test_a_union_of_tables_lists_no_keys_rather_than_one_tables() -> None:
    """Which of two tables the text meant is not known from where the key is: listing the
    first's keys would send the user to a table they did not write."""
    assert accepted_keys(_Outer, ["either", "rat"]) == ()
    assert unknown_key_message("rat", ()) == "not a key here (check the spelling and the table it is in)"
