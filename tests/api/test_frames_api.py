"""The frames commands through the real API server (a fake controller behind it) and the
command line: fields validated, partial updates, saved to the frames file, a failed save
leaves the frames in force unchanged (issue 12)."""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import pytest

from hexactl.adapters.cli.main import build_parser, main
from hexactl.adapters.cli.service_commands import FRAMES, _frames_request
from hexactl.adapters.files.frames_file import load_frames
from hexactl.control.frames import Frame
from hexactl.control.results import CommandResult
from hexactl.kinematics.geometry import Geometry
from tests.api.support import start_service
from tests.api.test_commands import send


@pytest.fixture
def framed(nominal: Geometry, tmp_path: Path) -> Iterator[SimpleNamespace]:
    running = start_service(nominal, tmp_path, frames_file=tmp_path / "frames.toml")
    yield running
    running.close()


def test_move_carries_its_frame_and_relative_to_the_controller(framed) -> None:
    send(framed, "enable")
    send(framed, "move", pose=[0, 0, 0, 5, 0, 0], frame="work")
    send(framed, "validate_pose", pose=[1, 0, 0, 0, 0, 0], frame="tool", relative=True)
    send(framed, "move", pose=[0, 0, 10, 0, 0, 0])
    assert framed.controller.frames_of_moves == [(Frame.WORK, False), (Frame.ZERO, False)]


@pytest.mark.parametrize("fields, fragment", [
    ({"frame": "platform"}, "frame"),
    ({"frame": "work", "relative": 1}, "relative"),
    ({"relative": "yes"}, "relative"),
])
def test_a_bad_frame_or_relative_is_an_invalid_request(framed, fields, fragment) -> None:
    reply = send(framed, "move", pose=[0, 0, 0, 0, 0, 0], **fields)
    assert reply["error"]["code"] == "invalid_request" and fragment in reply["error"]["message"]


def test_set_frames_merges_saves_and_clears(framed, tmp_path: Path) -> None:
    tool = send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    assert tool["frames"]["tool"] == [0, 0, 300, 0, 0, 0] and tool["frames"]["work"] == [0] * 6
    soft = {"lower": [-50, None, None, None, None, None], "upper": [50, None, None, None, None, None],
            "max_tilt_deg": 10}
    both = send(framed, "set_frames", work=[0, 0, 300, 0, 0, 0], soft_limits=soft)
    assert both["frames"]["tool"] == [0, 0, 300, 0, 0, 0] and both["frames"]["soft_limits"] == soft
    assert send(framed, "frames")["frames"] == both["frames"]
    saved = load_frames(tmp_path / "frames.toml")
    assert saved == framed.controller.frames and saved.soft_limits.max_tilt_deg == 10
    cleared = send(framed, "clear_frames")
    assert cleared["message"] == "frames cleared: poses relative to the zero posture"
    assert cleared["frames"]["tool"] == [0] * 6 and load_frames(tmp_path / "frames.toml").tool == (0,) * 6


@pytest.mark.parametrize("fields, fragment", [
    ({"tool": [0, 0, 300]}, "six numbers"),
    ({"work": [0, 0, 0, 0, 0, 200]}, "yaw 200 deg is outside [-180, 180] deg"),
    ({"soft_limits": {"max_tilt_deg": 95}}, "max_tilt_deg"),
    ({"soft_limits": {"lower": [1, 2, 3, 4, 5, 6], "upper": [0, 2, 3, 4, 5, 6]}}, "below its upper bound"),
    ({"pivot": [0, 0, 300]}, "pivot"),
    ({"soft_limits": {"uper": [None] * 6}}, "soft_limits.uper: not a key here; did you mean upper?"),
    ({"soft_limits": {"lower": [None] * 5 + [170], "upper": [None] * 5 + [-170]}},
     "soft_limits: yaw [170, -170] deg crosses ±180 deg, which soft limits do not support"),
])
def test_bad_frames_are_refused_naming_the_problem_and_change_nothing(framed, fields, fragment) -> None:
    reply = send(framed, "set_frames", **fields)
    assert reply["error"]["code"] == "invalid_request" and fragment in reply["error"]["message"]
    details = reply["error"]["details"]  # as for any invalid_request: a {field, problem} each
    assert details and all(set(d) == {"field", "problem"} for d in details), details
    assert any(fragment in f"{d['field']}: {d['problem']}" for d in details), details
    assert framed.controller.calls == []


def test_a_failed_save_keeps_the_frames_in_force(nominal: Geometry, tmp_path: Path) -> None:
    (tmp_path / "a file").write_text("")
    unwritable = start_service(nominal, tmp_path, frames_file=tmp_path / "a file" / "frames.toml")
    try:
        reply = send(unwritable, "set_frames", tool=[0, 0, 300, 0, 0, 0])
        assert reply["error"]["code"] == "write_failed" and "not in force: the ones before are" in reply["error"]["message"]
        assert unwritable.controller.frames.tool == (0,) * 6
    finally:
        unwritable.close()


def test_frames_on_a_full_disk_are_refused_saying_so_and_the_file_is_kept(framed, tmp_path: Path, monkeypatch,
                                                                           capsys) -> None:
    send(framed, "set_frames", tool=[0, 0, 100, 0, 0, 0])
    saved = (tmp_path / "frames.toml").read_bytes()

    def full_disk(descriptor, *arguments, **options):  # /dev/full: every write fails with ENOSPC
        os.close(descriptor)
        return open("/dev/full", *arguments, **options)

    monkeypatch.setattr(os, "fdopen", full_disk)
    calls = len(framed.controller.calls)
    reply = send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    # Found from outside: they were taken first, in force until put back once the write failed
    assert framed.controller.calls[calls:] == [], "the frames were in force before they were saved"
    assert reply["error"]["code"] == "write_failed", reply  # was file_not_found: no file was missing
    assert reply["error"]["message"] == (f"{tmp_path / 'frames.toml'}: the frames could not be saved: No space left on "
                                         "device; free some space there; they are not in force: the ones before are, "
                                         "and stay in the file; set them again once it can be written")
    assert framed.controller.frames.tool == (0, 0, 100, 0, 0, 0)
    assert main(["frames", "--tool", "z=300", "--api", framed.api]) == 1
    assert "check the name" not in capsys.readouterr().err  # file_not_found's hint, which misled
    monkeypatch.undo()
    assert (tmp_path / "frames.toml").read_bytes() == saved and sorted(tmp_path.glob(".frames.toml.*")) == []


def test_frames_not_saved_and_not_put_back_are_said_to_be_in_force(framed, tmp_path: Path, monkeypatch) -> None:
    """Found from outside (by reading): the frames before were put back unchecked, and the
    reply said "they are not in force" whatever that answered. The frames are taken once
    on disk, before they replace the file: a rename that fails then puts them back."""
    send(framed, "set_frames", tool=[0, 0, 100, 0, 0, 0])

    def full_disk(source, target):  # noqa: ANN001, ANN202
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    calls = []

    def second_refused(frames):  # noqa: ANN001, ANN202
        calls.append(frames)
        if len(calls) == 1:
            framed.controller.frames = frames
            return CommandResult.success("frames set")
        return CommandResult.failure("busy", "the platform is moving: wait until it is at rest, or stop it")

    monkeypatch.setattr(os, "replace", full_disk)
    monkeypatch.setattr(framed.controller, "set_frames", second_refused)
    reply = send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    assert reply["error"]["code"] == "write_failed", reply
    assert reply["error"]["message"].endswith(
        "free some space there; they are in force all the same: putting the ones before back was refused (the "
        "platform is moving: wait until it is at rest, or stop it), and a restart would restore the file's; set them "
        "again once it can be written"), reply
    assert framed.controller.frames.tool == (0, 0, 300, 0, 0, 0)


def test_a_frames_file_edited_under_the_service_is_named_and_kept_aside_not_overwritten(framed, tmp_path: Path,
                                                                                           capsys) -> None:
    """The service reads its frames file at start only: an operator who edits the soft limits
    in it must learn they are not in force, and the edit is not lost at the next change."""
    path = tmp_path / "frames.toml"
    send(framed, "set_frames", soft_limits={"lower": [-50] + [None] * 5, "upper": [50] + [None] * 5})
    assert "message" not in send(framed, "frames") or not send(framed, "frames")["message"]
    edited = path.read_text().replace("x = 50.0", "x = 10.0")
    path.write_text(edited)
    shown = send(framed, "frames")
    assert shown["frames"]["soft_limits"]["upper"][0] == 50  # what is in force, not the file
    assert "no longer holds them: it was changed" in shown["message"] and "reads that file at start only" in shown["message"]
    assert main(["frames", "--api", framed.api]) == 0 and "no longer holds them" in capsys.readouterr().out
    changed = send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    assert "had been changed since the service read it" in changed["message"]
    [aside] = sorted(tmp_path.glob("frames.toml.changed-*"))
    assert str(aside) in changed["message"] and aside.read_text() == edited
    assert load_frames(path) == framed.controller.frames and load_frames(path).soft_limits.upper[0] == 50
    assert not send(framed, "frames").get("message")  # the file holds the frames in force again
    send(framed, "set_frames", tool=[0, 0, 200, 0, 0, 0])
    assert sorted(tmp_path.glob("frames.toml.changed-*")) == [aside]  # only a changed file is kept aside


def test_a_frames_file_removed_under_the_service_is_named(framed, tmp_path: Path) -> None:
    send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    (tmp_path / "frames.toml").unlink()
    said = send(framed, "frames")["message"]
    assert "it was removed" in said and "restart the service to use the file's" not in said, said  # there is none
    assert "a restart would start with no frames and no soft limits: set them again (hexactl frames)" in said, said
    assert "changed since" not in send(framed, "set_frames", tool=[0, 0, 100, 0, 0, 0])["message"]
    assert load_frames(tmp_path / "frames.toml").tool == (0, 0, 100, 0, 0, 0)


def test_an_unreadable_frames_file_is_kept_aside_whole(framed, tmp_path: Path) -> None:
    (tmp_path / "frames.toml").write_text("work = [0, 0\n")
    assert "it cannot be used now" in send(framed, "frames")["message"]
    send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0])
    [aside] = sorted(tmp_path.glob("frames.toml.changed-*"))
    assert aside.read_text() == "work = [0, 0\n"


def test_the_command_line_sets_shows_and_moves_in_frames(framed, capsys) -> None:
    api = ["--api", framed.api]
    assert main(["frames", "--tool", "z=300", "--soft-lower", "x=-50", "--soft-upper", "x=50", *api]) == 0
    out = capsys.readouterr().out
    assert "tool frame     x    0.000 mm  y    0.000 mm  z  300.000 mm" in out
    assert "soft limits    x -50..50 mm" in out
    assert framed.controller.frames.soft_limits.lower[0] == -50
    assert main(["frames", *api]) == 0 and "soft limits    x -50..50 mm" in capsys.readouterr().out
    assert main(["enable", *api]) == 0
    assert main(["move", "--frame", "tool", "--relative", "pitch=5", *api]) == 0
    assert framed.controller.frames_of_moves[-1] == (Frame.TOOL, True)
    moves = len(framed.controller.frames_of_moves)
    assert main(["move", "--frame", "tool", "pitch=5", *api]) == 2  # bad input: the service refused it, exit 1
    assert "--frame tool moves relative to where the tool is" in capsys.readouterr().err
    assert len(framed.controller.frames_of_moves) == moves  # not sent
    assert main(["frames", "--clear", "--tool", "z=1", *api]) == 2
    assert "--clear takes no other frame option" in capsys.readouterr().err
    assert main(["frames", "--clear", *api]) == 0 and "frames         none" in capsys.readouterr().out


def test_the_command_line_changes_only_the_soft_limits_it_names(framed, capsys) -> None:
    """``frames --max-tilt 12`` set a tilt bound and removed the x, y, z bounds (the API
    replaces the soft limits whole, and the command line sent only what it was given): an
    operator adding one limit lost the others."""
    api = ["--api", framed.api]

    def soft() -> tuple:
        limits = framed.controller.frames.soft_limits
        return limits.lower, limits.upper, limits.max_tilt_deg

    assert main(["frames", "--soft-lower", "x=-50,z=-10", "--soft-upper", "x=50", *api]) == 0
    assert main(["frames", "--max-tilt", "12", *api]) == 0
    assert soft() == ((-50, None, -10, None, None, None), (50, None, None, None, None, None), 12)
    assert "soft limits    x -50..50 mm, z ≥ -10 mm, tilt ≤ 12 deg" in capsys.readouterr().out
    assert main(["frames", "--soft-lower", "x=-40,z=none", "--tool", "z=300", *api]) == 0
    assert soft() == ((-40, None, None, None, None, None), (50, None, None, None, None, None), 12)
    assert framed.controller.frames.tool == (0, 0, 300, 0, 0, 0)
    assert main(["frames", "--max-tilt", "none", "--soft-upper", "yaw=5", *api]) == 0
    assert soft() == ((-40, None, None, None, None, None), (50, None, None, None, None, 5), None)
    assert "soft limits    x -40..50 mm, yaw ≤ 5 deg" in capsys.readouterr().out
    assert main(["frames", "--soft-upper", "x=-45", *api]) == 1  # below its lower bound: the service says so
    assert "each lower bound must be below its upper bound: x [-40, -45]" in capsys.readouterr().err
    assert soft() == ((-40, None, None, None, None, None), (50, None, None, None, None, 5), None)


def test_the_command_line_sends_only_the_soft_limits_it_names() -> None:
    """It used to read the soft limits in force, change them and set them whole: another
    client's change between the two was lost, and a refused read set nothing. The service
    now changes them against those in force when it takes the request."""
    arguments = build_parser().parse_args(["frames", "--soft-lower", "x=-40,z=none", "--max-tilt", "none",
                                           "--tool", "z=300"])
    assert _frames_request(arguments) == ("set_frames", {
        "tool": [0, 0, 300, 0, 0, 0], "soft_limit_changes": {"lower": {"x": -40, "z": None}, "max_tilt_deg": None}})


def test_set_frames_changes_the_soft_limits_it_is_given_and_keeps_the_others(framed, tmp_path: Path) -> None:
    soft = {"lower": [-50, None, -10, None, None, None], "upper": [50, None, None, None, None, None],
            "max_tilt_deg": None}
    send(framed, "set_frames", soft_limits=soft)
    tilt = send(framed, "set_frames", soft_limit_changes={"max_tilt_deg": 12})
    assert tilt["frames"]["soft_limits"] == {**soft, "max_tilt_deg": 12}
    changed = send(framed, "set_frames", tool=[0, 0, 300, 0, 0, 0],
                   soft_limit_changes={"lower": {"x": -40, "z": None}, "upper": {"yaw": 5}})
    assert changed["frames"]["soft_limits"] == {"lower": [-40, None, None, None, None, None],
                                                "upper": [50, None, None, None, None, 5], "max_tilt_deg": 12}
    assert changed["frames"]["tool"] == [0, 0, 300, 0, 0, 0]
    assert load_frames(tmp_path / "frames.toml") == framed.controller.frames
    untilted = send(framed, "set_frames", soft_limit_changes={"max_tilt_deg": None})
    assert untilted["frames"]["soft_limits"]["max_tilt_deg"] is None
    assert untilted["frames"]["soft_limits"]["lower"] == changed["frames"]["soft_limits"]["lower"]


@pytest.mark.parametrize("changes, fragment", [
    ({"upper": {"x": -60}}, "each lower bound must be below its upper bound: x [-50, -60]"),
    ({"lower": {"tilt": 3}}, "soft_limit_changes.lower.tilt"),
    ({"lower": {"x": "3"}}, "soft_limit_changes.lower.x"),
    ({"max_tilt_deg": 95}, "soft_limit_changes.max_tilt_deg: Input should be less than or equal to 90"),
    ({"upper": [50, None, None, None, None, None]}, "soft_limit_changes.upper"),
])
def test_soft_limit_changes_that_break_a_rule_are_refused_and_change_nothing(framed, changes, fragment) -> None:
    send(framed, "set_frames", soft_limits={"lower": [-50] + [None] * 5, "upper": [None] * 6})
    before = framed.controller.frames
    reply = send(framed, "set_frames", soft_limit_changes=changes)
    assert reply["error"]["code"] == "invalid_request" and fragment in reply["error"]["message"], reply
    assert framed.controller.frames == before


def test_soft_limits_are_replaced_or_changed_not_both(framed) -> None:
    reply = send(framed, "set_frames", soft_limits={"max_tilt_deg": 10}, soft_limit_changes={"max_tilt_deg": 12})
    assert reply["error"]["code"] == "invalid_request", reply
    assert "soft_limits replaces all of them and soft_limit_changes some: give one, not both" in reply["error"]["message"]
    assert framed.controller.calls == []


def test_the_command_line_knows_every_frame_the_controller_does() -> None:
    assert FRAMES == tuple(frame.value for frame in Frame)


@pytest.mark.parametrize("text, fragment", [
    ("tool = [0, 0, 300", "not valid TOML"),
    ("[soft_limits.lower]\ntilt = 3\n", "soft_limits.lower: unknown axis tilt; the axes are x, y, z, roll, pitch, yaw"),
    ("tool = [0, 0, 300, 0, 0, 0]\npivot = 1\n", "pivot: not a key here; the keys here are work, tool, soft_limits"),
    ("[soft_limits]\nmax_tilt = 5\n",
     "soft_limits.max_tilt: not a key here; did you mean max_tilt_deg? the keys here are lower, upper, max_tilt_deg"),
    ("", "empty (no work, tool or soft_limits)"),  # found from outside: it started the service with no soft limits
    ("# hexactl operator frames\n\n", "empty"),
    # named as the operator wrote it, not by its place in a list the file does not show (it said upper[5])
    ('[soft_limits.upper]\nyaw = "5"\n', 'soft_limits.upper.yaw: must be a number, not the string "5"'),
    ("[soft_limits.lower]\nx = nan\n", "soft_limits.lower.x: must be a finite number"),
    ("[soft_limits]\nlower = [1, 2, 3, 4, 5, nan]\n", "soft_limits.lower[5]: must be a finite number"),
])
def test_a_frames_file_that_cannot_be_used_is_named_with_the_problem(tmp_path: Path, text, fragment) -> None:
    from hexactl.adapters.files.frames_file import FramesFileError

    path = tmp_path / "frames.toml"
    path.write_text(text)
    with pytest.raises(FramesFileError, match=str(path)) as refused:
        load_frames(path)
    assert fragment in str(refused.value)


def test_a_sequence_says_its_frame_inline_and_in_a_file(framed, tmp_path: Path) -> None:
    send(framed, "enable")
    inline = {"name": "tilts", "frame": "work", "waypoints": [{"pose": [0, 0, 0, 5, 0, 0]}]}
    send(framed, "play", sequence=inline)
    assert framed.controller.sequence.frame == "work"
    assert type(framed.controller.sequence.planning_waypoints()[0].pose).__name__ == "ToolInWorkMmDeg"
    (tmp_path / "tilts.toml").write_text('name = "tilts"\nframe = "work"\n[[waypoint]]\npose = [0, 0, 0, 0, 5, 0]\n')
    send(framed, "play", sequence="tilts.toml")
    assert framed.controller.sequence.frame == "work"
    (tmp_path / "bad.toml").write_text('name = "bad"\nframe = "tool"\n[[waypoint]]\npose = [0, 0, 0, 0, 5, 0]\n')
    refused = send(framed, "play", sequence="bad.toml")
    assert refused["error"]["code"] == "invalid_sequence" and "frame" in refused["error"]["message"]
