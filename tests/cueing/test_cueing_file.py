"""The cueing files: the parameters TOML and the vehicle trajectory CSV, and their errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexactl.adapters.files.cueing_file import (
    CueingFileError,
    load_cueing_parameters,
    load_vehicle_trajectory,
    parse_cueing_parameters,
    parse_vehicle_trajectory,
)
from hexactl.cueing.parameters import CueingParameters

REPOSITORY = Path(__file__).resolve().parents[2]

HEADER = "t_s,f_x,f_y,f_z,omega_x,omega_y,omega_z"


def test_the_shipped_parameters_file_holds_the_defaults_and_sets_every_key() -> None:
    path = REPOSITORY / "config" / "cueing.toml"
    assert load_cueing_parameters(path) == CueingParameters()
    text = path.read_text(encoding="utf-8")
    for table, model in CueingParameters().model_dump().items():
        assert f"[{table}]" in text
        for key in model:
            assert f"\n{key} = " in text, f"{table}.{key} is not in config/cueing.toml"


def test_a_key_left_out_keeps_its_default() -> None:
    parameters = parse_cueing_parameters("[tilt]\nrate_limit_deg_s = 2.0\n", "mine.toml")
    assert parameters.tilt.rate_limit_deg_s == 2.0
    assert parameters.translational == CueingParameters().translational


@pytest.mark.parametrize(("text", "expected"), [
    ("[tilt]\nrate_limt_deg_s = 2.0\n", "mine.toml: tilt.rate_limt_deg_s: not a key here; did you mean rate_limit_deg_s? "
                                       "the keys here are gain, break_rad_s, damping, rate_limit_deg_s, limit_deg"),
    ("[translational]\nbreak_rad_s = [1.0, -1.0, 2.0]\n",
     "mine.toml: translational.break_rad_s[1]: Input should be greater than 0"),
    ("[translational]\ngain = [1.0, 1.0]\n", "mine.toml: translational.gain: too few values, one per axis"),
    ("[translational]\ngain = [1.0, 1.0, 1.0, 1.0]\n", "mine.toml: translational.gain: too many values, one per axis"),
    ("[translational]\ngain = 0.5\n", "mine.toml: translational.gain: must be a list of numbers"),
    ("[tilt]\nlimit_deg = nan\n", "mine.toml: tilt.limit_deg: must be a finite number"),
    ("[workspace]\nlimiter_knee = 0.98\n", "mine.toml: workspace: limiter_knee 0.98 must be below limiter_ceiling 0.97"),
    # Found from outside: taken, and the lane change's y then ran at 911 mm/s
    ("[workspace]\nuse_fraction = 0.99\n", "mine.toml: workspace: use_fraction 0.99 must be at most limiter_ceiling 0.97"),
    ("[workspace]\nmax_gain = 1e4\n", "mine.toml: workspace.max_gain: Input should be less than or equal to 100"),
    ("[wash]\ngain = 1\n", "mine.toml: wash: not a key here; the keys here are translational, rotational, tilt, workspace"),
    ("[tilt\n", "mine.toml: not valid TOML"),
])
def test_a_bad_parameters_file_is_refused_naming_the_file_and_the_key(text: str, expected: str) -> None:
    with pytest.raises(CueingFileError) as refused:
        parse_cueing_parameters(text, "mine.toml")
    assert expected in str(refused.value)


def test_every_problem_of_a_parameters_file_is_named_at_once() -> None:
    with pytest.raises(CueingFileError) as refused:
        parse_cueing_parameters("[tilt]\nlimit_deg = 100.0\ndamping = 0\n", "mine.toml")
    lines = str(refused.value).splitlines()
    assert [line.split(":")[1].strip() for line in lines] == ["tilt.damping", "tilt.limit_deg"]


def test_an_unreadable_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(CueingFileError, match="missing.toml: no such file: check the name"):
        load_cueing_parameters(tmp_path / "missing.toml")
    with pytest.raises(CueingFileError, match="missing.csv: no such file"):
        load_vehicle_trajectory(tmp_path / "missing.csv")
    with pytest.raises(CueingFileError, match="a folder, not a file: name a file in it"):
        load_vehicle_trajectory(tmp_path)  # a directory


def test_the_shipped_vehicle_trajectories_load_at_100_hz(vehicles) -> None:
    for name, vehicle in vehicles.items():
        assert vehicle.period_s == pytest.approx(0.01), name
        assert 10.0 <= vehicle.times_s[-1] <= 15.0, name
        np.testing.assert_allclose(vehicle.specific_force[0], [0.0, 0.0, 9.81])  # starts at rest or cruising
    assert vehicles["braking"].specific_force[:, 0].min() == pytest.approx(-7.0)
    assert np.abs(vehicles["lane_change"].specific_force[:, 1]).max() == pytest.approx(3.5)


def test_a_vehicle_file_takes_its_columns_by_name_in_any_order() -> None:
    text = "omega_z,t_s,f_x,f_y,f_z,omega_x,omega_y,speed\n0.1,0.0,1,2,9.81,0,0,25\n0.2,0.5,3,4,9.81,0,0,25\n"
    vehicle = parse_vehicle_trajectory(text, "mine.csv")
    assert vehicle.period_s == 0.5
    np.testing.assert_array_equal(vehicle.specific_force, [[1, 2, 9.81], [3, 4, 9.81]])
    np.testing.assert_array_equal(vehicle.angular_rate, [[0, 0, 0.1], [0, 0, 0.2]])


def test_a_spreadsheets_byte_order_mark_is_not_part_of_the_first_column(tmp_path: Path) -> None:
    path = tmp_path / "exported.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,0,9.81,0,0,0\n").encode())
    assert len(load_vehicle_trajectory(path)) == 2


def rows(*times: float, decimals: int | None = None) -> str:
    """A file at rest at ``times`` (s), written as Python writes them or to ``decimals``."""
    written = [f"{t}" if decimals is None else f"{t:.{decimals}f}" for t in times]
    return HEADER + "\n" + "".join(f"{t},0,0,9.81,0,0,0\n" for t in written)


@pytest.mark.parametrize(("text", "expected"), [
    ("", "mine.csv: empty"),
    ("t_s,f_x,f_y,f_z,omega_x,omega_y\n0,0,0,9.81,0,0\n", "mine.csv: line 1: missing column omega_z"),
    ("t_s,f_x,f_y,f_z,omega_x,omega_y,omega_Z\n", "missing column omega_z (the header has omega_Z instead"),
    # found from outside: the first f_x was taken, the real one after it ignored
    (HEADER + ",f_x\n0,50,0,9.81,0,0,0,-3\n", "mine.csv: line 1: column f_x named more than once: which is meant cannot"),
    (rows(0.0, 0.01, 0.02, 0.04, 0.05, decimals=3),
     "mine.csv: line 5, column t_s: 0.04 s is 0.02 s after the sample before it, where the file's samples are 0.01 s "
     "apart (its median step; times written to 0.001 s): samples must be evenly spaced (resample the trajectory"),
    (rows(0.0, 0.01, 0.01), "mine.csv: line 4, column t_s: 0.01 s is not after the sample before it (0.01 s): "
                            "times must increase"),
    (rows(0.0, 0.01, 0.005), "mine.csv: line 4, column t_s: 0.005 s is not after the sample before it"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,x,9.81,0,0,0\n", "mine.csv: line 3, column f_y: 'x' is not a finite number"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,0,9.81,0,inf,0\n", "mine.csv: line 3, column omega_y: 'inf' is not a finite"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,,9.81,0,0,0\n", "mine.csv: line 3, column f_y: nothing is not a finite number"),
    # as measurement files and stream text: what float() also takes is a typing error, not a number
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,1_0,0,9.81,0,0,0\n", "mine.csv: line 3, column f_x: '1_0' is not a finite "
                                                              "number (write digits 0-9"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.0\uff11,0,0,9.81,0,0,0\n", "mine.csv: line 3, column t_s: '0.0\uff11' is not a"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,0,9.81\n", "mine.csv: line 3: has 4 fields, the header has 7"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,0,9.81,0,0,0,5,6\n", "mine.csv: line 3: has 9 fields, the header has 7"),
    (rows(0.0), "mine.csv: 1 samples: a vehicle trajectory needs at least two lines of values"),
    # found from outside: one glitch of 1e308 overflowed the filter (a traceback), one of 1e6 silenced every cue
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,1e308,0,9.81,0,0,0\n", "mine.csv: line 3, column f_x: 1e+308 m/s² is beyond "
                                                               "±294.3 m/s² (30 g)"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,-1e6,0,9.81,0,0,0\n", "line 3, column f_x: -1e+06 m/s² is beyond"),
    (HEADER + "\n0,0,0,9.81,0,0,0\n0.01,0,0,9.81,0,0,57.3\n", "mine.csv: line 3, column omega_z: 57.3 rad/s is beyond "
                                                               "±35 rad/s (2000 deg/s, a gyro's full scale): in deg/s?"),
])
def test_a_bad_vehicle_file_is_refused_naming_the_line_and_column(text: str, expected: str) -> None:
    with pytest.raises(CueingFileError) as refused:
        parse_vehicle_trajectory(text, "mine.csv")
    assert expected in str(refused.value)


@pytest.mark.parametrize(("f_z", "mistake"), [(1.0, "in g"), (0.0, "without gravity"), (-9.81, "z down")])
def test_a_vehicle_file_in_the_wrong_units_or_axes_is_refused_naming_f_z(f_z: float, mistake: str) -> None:
    """It was taken: a file in g, or with gravity left out, or in z-down (aerospace) axes
    planned a cue with a z jolt of about 1 g and the wrong tilts, and said nothing."""
    text = HEADER + "\n" + "".join(f"{n / 100},0.1,0,{f_z},0,0,0\n" for n in range(20))
    with pytest.raises(CueingFileError) as refused:
        parse_vehicle_trajectory(text, "mine.csv")
    message = str(refused.value)
    assert message.startswith(f"mine.csv: column f_z: {f_z:g} m/s² (median over the file)")
    assert "+9.81 m/s²" in message and "in g" in message and "without gravity" in message and "z down" in message


def test_a_vehicle_file_whose_f_z_swings_about_one_g_is_taken() -> None:
    """A flight: pulled up at 2.5 g and pushed over to 0.2 g, 1 g most of the time."""
    values = [9.81] * 12 + [24.5] * 4 + [2.0] * 4
    text = HEADER + "\n" + "".join(f"{n / 100},0,0,{f_z},0,0,0\n" for n, f_z in enumerate(values))
    assert len(parse_vehicle_trajectory(text, "mine.csv")) == 20


def test_times_rounded_in_the_text_are_uniform_and_blank_lines_are_skipped_keeping_line_numbers() -> None:
    vehicle = parse_vehicle_trajectory(rows(0.0, 0.01, 0.02, 0.03) + "\n" + "0.04,0,0,9.81,0,0,0\n", "mine.csv")
    assert len(vehicle) == 5 and vehicle.period_s == pytest.approx(0.01)
    with pytest.raises(CueingFileError, match="line 7, column t_s"):
        parse_vehicle_trajectory(rows(0.0, 0.01, 0.02, 0.03, decimals=3) + "\n" + "0.050,0,0,9.81,0,0,0\n",
                                 "mine.csv")


@pytest.mark.parametrize(("rate_hz", "decimals"), [(60, 4), (60, 3), (120, 4), (100, 2), (30, 2)])
def test_evenly_spaced_times_rounded_to_their_decimals_are_taken_at_the_files_rate(rate_hz: int, decimals: int) -> None:
    """Found from outside: 60 Hz written to 4 decimals (0.0167, 0.0333, …) was refused as
    not evenly spaced, its steps 0.0167 and 0.0166 further apart than 0.1 % of the first."""
    count = 6 * rate_hz + 1
    vehicle = parse_vehicle_trajectory(rows(*(n / rate_hz for n in range(count)), decimals=decimals), "mine.csv")
    assert len(vehicle) == count
    assert vehicle.period_s == pytest.approx(1 / rate_hz, abs=10.0**-decimals / (count - 1))  # first to last


def evenly(start_s: float, period_s: float, count: int) -> list[float]:
    return [start_s + n * period_s for n in range(count)]


@pytest.mark.parametrize(("times", "expected"), [
    (evenly(0.0, 1 / 60, 180) + evenly(181 / 60, 1 / 60, 180),  # one sample missing at 3 s
     "mine.csv: line 182, column t_s: 3.0167 s is 0.0334 s after the sample before it, where the file's samples are "
     "0.0167 s apart (its median step; times written to 0.0001 s)"),
    (evenly(0.0, 1 / 60, 181) + evenly(3.02, 1 / 50, 150),  # 60 Hz, then 50 Hz
     "mine.csv: line 183, column t_s: 3.02 s is 0.02 s after the sample before it, where the file's samples are 0.0167 s"),
    (evenly(0.0, 0.01, 500) + evenly(5.0, 1 / 101, 505),  # 100 Hz, then 101 Hz: each step as even as the rounding
     "s off the file's even spacing (0.0099503 s, from its first sample to its last; times written to 0.0001 s): the "
     "rate changes along the file: samples must be evenly spaced (resample the trajectory at one rate)"),
])
def test_a_gap_or_a_change_of_rate_is_refused_whatever_the_rounding(times: list[float], expected: str) -> None:
    with pytest.raises(CueingFileError) as refused:
        parse_vehicle_trajectory(rows(*times, decimals=4), "mine.csv")
    assert expected in str(refused.value)


def test_a_shipped_trajectory_is_found_by_its_name_and_a_missing_file_names_them(tmp_path, monkeypatch) -> None:
    from hexactl.adapters.files.cueing_file import load_vehicle_trajectory, shipped_vehicles

    monkeypatch.chdir(tmp_path)  # not the checkout: as an operator runs hexactl cue braking anywhere
    assert shipped_vehicles() == ["braking", "lane_change"]
    assert load_vehicle_trajectory("braking").period_s == pytest.approx(0.01)
    with pytest.raises(CueingFileError, match="no such file; the shipped trajectories are braking, lane_change"):
        load_vehicle_trajectory("brakign")
