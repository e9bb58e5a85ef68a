"""Driving a running controller through its API for a campaign: enable, move and wait
until the platform has settled, lock and unlock legs, swap calibrations.

Every method returns or waits on status records (the API's telemetry record: poses
relative to the zero posture in mm and degrees, legs in sensor mm). A controller in
FAULT or ESTOP, or a refusal, ends the campaign with :class:`CampaignError`: what was
measured is saved, and the same command resumes after the operator has dealt with it.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from hexactl.adapters.api.client import CommandError, HexactlClient, ServiceUnavailable
from hexactl.adapters.api.protocol import GOAL_TOLERANCE
from hexactl.control.results import REPORT_SILENT_S

Record = dict[str, Any]
"""A status record (``status`` reply's ``status``)."""

ZERO_POSE = (0.0,) * 6

MOVE_ATTEMPTS = 3
"""How many times :meth:`PlatformDriver.move` sends a move that the API answered with
``loop_timeout`` (the loop's verdict came too late for it, on a loaded host): the move may
or may not have run, so the driver waits for rest and sends it again (a move to where the
platform already is ends at once). Likewise a move answered ``loop_silent`` (the loop's
process held up past a second: not sent), once the loop reports again, and a move the
service braked short of its goal by itself when its API fell silent
(``command_link_silent``, a loaded host). Any command refused ``expired`` (its deadline
passed in the loop's queue, on a loaded host: not carried out) is sent again as often."""

_LATE = ("loop_timeout", "loop_silent", "expired")

_SILENT_API = ("command_link_silent", "command_link_heard")
"""The events of the service's own brake when its API fell silent, which no one sent."""

FAULT_CLEAR_S = 2.0
"""How long enabling waits for actuators that report a fault to clear it (they do after
a reset's CLEAR_FAULT, once their E-stop hold-off has passed)."""


class CampaignError(Exception):
    """The campaign cannot go on; the message says why and what to do."""


class ControllerFault(CampaignError):
    """The controller latched FAULT or ESTOP, or an actuator is in fault: ``summary``
    says what; ``resettable``: a fault, not an E-stop (which is someone's decision)."""

    def __init__(self, summary: str, resettable: bool) -> None:
        self.summary = summary
        self.resettable = resettable
        super().__init__(f"{summary}: reset it and enable it, then run the same command again to resume")


@dataclass(frozen=True, slots=True)
class SettleCriteria:
    """When a platform at rest counts as settled: every leg's feedback stayed within
    ``tolerance_mm`` for ``window_s`` of controller time (the records' ``t``). A move that
    has not ended ``timeout_s`` after its planned duration is an error; ``poll_s`` is the
    status polling interval. A measurement is kept only if every leg is still within
    ``still_tolerance_mm`` of the settled record once it has been taken: a fifth of the
    simulated theodolites' noise, and room for a real leg's sensor noise and drift over
    the minutes a manual measurement takes."""

    window_s: float = 0.05
    tolerance_mm: float = 0.002
    timeout_s: float = 15.0
    poll_s: float = 0.01
    still_tolerance_mm: float = 0.05


class PlatformDriver:
    """The campaign's side of the API: one request at a time on ``client``."""

    def __init__(self, client: HexactlClient, settle: SettleCriteria = SettleCriteria()) -> None:
        self.client = client
        self.settle = settle

    def status(self) -> Record:
        """The current status record; :class:`CampaignError` if FAULT or ESTOP is latched."""
        record = self.client.call("status")["status"]
        if record["state"] in ("fault", "estop"):
            faults = "; ".join(f"{fault['code']}: {fault['message']}" for fault in record["faults"]) or "no reason given"
            raise ControllerFault(f"the controller is in {record['state']} ({faults})", record["state"] == "fault")
        return record

    def prepare(self) -> Record:
        """Bring the controller to an enabled platform at rest, no sequence, no leg
        locked (what an interrupted campaign may have left); returns the settled record."""
        record = self.status()
        if record["state"] == "disabled":
            self._enable()
        if record["sequence"] is not None:
            self._call("abort")
        elif record["motion"] != "holding":
            self._call("stop")
        record = self.wait_settled(0.0)
        if record["locked_leg"] is not None:
            self._call("leg_unlock")
            record = self.status()
        return record

    def reset(self) -> None:
        """Clear a latched FAULT (``reset``, which ends disabled); :meth:`prepare` enables
        again. A reset answered ``loop_timeout`` may still be carried out: the state says."""
        self._call("reset", harmless=("loop_timeout",))
        deadline = time.monotonic() + self.settle.timeout_s
        while self.client.call("status")["status"]["state"] != "disabled":
            if time.monotonic() > deadline:
                raise CampaignError("the controller did not reset")
            time.sleep(self.settle.poll_s)

    def require_calibration(self, calibration_id: str, what: str, advice: str) -> None:
        """:class:`CampaignError` unless the controller runs ``calibration_id`` (``what``
        names it, ``advice`` says what to do, for the message)."""
        active = self.status()["calibration_id"]
        if active != calibration_id:
            raise CampaignError(f"the controller runs calibration {active}, not {what} ({calibration_id}): {advice}")

    def move(self, pose: Sequence[float], *, settle: bool = True) -> Record:
        """Move to ``pose`` (relative mm/deg) and wait until the move has ended and, with
        ``settle``, the legs are steady (sent again after a ``loop_timeout``, see
        :data:`MOVE_ATTEMPTS`). Raises :class:`CommandError` if the controller refuses the
        move (e.g. ``path_violation``) and :class:`CampaignError` on a fault, when no
        attempt got a verdict, or when someone cut the move short of its goal."""
        for _ in range(MOVE_ATTEMPTS):
            events = self.status()["events"]
            since = events[-1]["seq"] if events else 0
            try:
                reply = self.client.call("move", pose=[float(value) for value in pose])
                record = self.wait_settled(float(reply["duration"]), settle=settle)
            except CommandError as error:
                self._latched(error)
                if error.code not in _LATE:
                    raise
                self.wait_settled(0.0, settle=False)
                continue
            if max(abs(at - aim) for at, aim in zip(record["pose_command"], reply["goal"])) <= GOAL_TOLERANCE:
                return record
            # Stopped short: measured here, the posture or waypoint would not be the planned one.
            after = self.client.call("events", after=since)["events"]  # all of them: a record carries the last 8
            ours = next((n for n, event in enumerate(after) if event["code"] == "move"), len(after))
            cause = after[ours + 1:]
            if not cause or any(event["code"] not in _SILENT_API for event in cause):
                told = "; ".join(f"{event['code']}: {event['message']}"
                                 + (f", sent by {event['sender']}" if event["sender"] else "") for event in cause)
                raise CampaignError(f"the move to {list(pose)} stopped short of its goal, at {record['pose_command']} "
                                    f"({told or 'the service recorded no cause'}): is another client driving the "
                                    "platform? Nothing was measured there; run the same command again to resume")
        raise CampaignError(f"the controller's API gave no verdict on the move to {list(pose)} in time, "
                            f"{MOVE_ATTEMPTS} times (loop_timeout or expired), or the service braked it when its API "
                            "fell silent (command_link_silent): the host is too loaded for it; stop other work on it or "
                            "raise --timeout, then run the same command again to resume")

    def confirm_still(self, settled: Record) -> None:
        """Check, once a measurement of the platform settled at ``settled`` (a
        :meth:`move`'s record) has been taken, that it still holds there, enabled: the
        measurement may be kept. Raises :class:`ControllerFault` if a fault or E-stop
        latched meanwhile (a stall that tripped the actuators' watchdog, say), and
        :class:`CampaignError` if the platform moved or was disabled without one; either
        way the measurement is not kept, and a resumed campaign takes it again."""
        record = self.status()
        moved = _moved(settled, record) if _heard(record) else float("inf")
        swapped = record["calibration_id"] != settled["calibration_id"]  # a ramp smaller than the tolerance, too
        if (record["state"] != "enabled" or record["motion"] != "holding" or moved > self.settle.still_tolerance_mm
                or swapped):
            raise CampaignError(f"the platform did not hold still while it was measured ({record['state']}, "
                                f"{record['motion']}, legs moved by up to {moved:.4f} mm"
                                + (f", calibration {settled['calibration_id']} → {record['calibration_id']}" if swapped else "")
                                + "): is another client driving it? The measurement was not kept; run the same command "
                                "again to measure it again")

    def lock(self, leg: int) -> Record:
        """Lock ``leg`` (1–6) where it is; returns the record with the lock in place."""
        return self._settled_after("leg_lock", leg=leg)

    def unlock(self) -> Record:
        return self._settled_after("leg_unlock")

    def load_calibration(self, toml: str, source: str) -> Record:
        """Send a calibration's text, ``source`` saying where it came from (the service
        records it: telemetry's ``calibration_source``, its log); returns the settled record
        once it is ramped in."""
        return self._settled_after("load_calibration", toml=toml, source=source)

    def return_to_calibration(self, calibration_id: str, toml: str, source: str) -> Record:
        """Make calibration ``calibration_id`` (``toml``: its text, from ``source``) active
        again after a load: by rolling the load back or, where that does not lead to it, by
        loading it (the service restarted since, with an undo history that starts empty; or
        another client loaded one since). Returns the settled record."""
        self._call("rollback_calibration", harmless=("no_previous_calibration",))
        record = self.wait_settled(0.0)
        return record if record["calibration_id"] == calibration_id else self.load_calibration(toml, source)

    def wait_settled(self, duration_s: float, *, settle: bool = True) -> Record:
        """Wait (at most ``duration_s`` + the criteria's timeout) until the platform holds
        with no sequence playing and, with ``settle``, until every leg's feedback has been
        steady for the criteria's window. Returns the last record."""
        criteria = self.settle
        deadline = time.monotonic() + duration_s + criteria.timeout_s
        reference: Record | None = None
        while True:
            record = self.status()
            if record["motion"] == "holding" and record["sequence"] is None and _heard(record) and _current(record):
                if not settle:
                    return record
                if reference is None or _moved(reference, record) > criteria.tolerance_mm:
                    reference = record
                elif record["t"] - reference["t"] >= criteria.window_s:
                    return record
            else:
                reference = None
            if time.monotonic() > deadline:
                # A held-up loop's last report may say "holding": the loop is what to look at.
                why = "" if _current(record) else (f": the control loop has sent no report for "
                                                   f"{record['loop']['report_age_s']:.1f} s (its process is stopped "
                                                   "or hung; see hexactl status)")
                raise CampaignError(f"the platform did not settle within {duration_s + criteria.timeout_s:.1f} s "
                                    f"(motion {record['motion']}, legs {record['leg_feedback']}){why}")
            time.sleep(criteria.poll_s)

    def _enable(self) -> None:
        """Enable, waiting for actuators that are still booting (``heartbeat_missing``) or
        clearing a fault after a reset (``actuator_fault``, for :data:`FAULT_CLEAR_S`), and
        asking again after a verdict that came too late for the API (``loop_timeout``: if
        the first was carried out, the next answers that it is already enabled) or a loop
        held up past a second (``loop_silent``: not sent)."""
        start = time.monotonic()
        while True:
            try:
                self.client.call("enable")
                return
            except CommandError as error:
                waited = time.monotonic() - start
                if error.code == "actuator_fault" and waited > FAULT_CLEAR_S:
                    raise ControllerFault(f"an actuator is in fault ({error.message})", True) from None
                if error.code not in ("heartbeat_missing", "actuator_fault", "loop_timeout", "loop_silent") \
                        or waited > self.settle.timeout_s:
                    raise CampaignError(f"cannot enable the actuators: {error}") from None
            time.sleep(0.05)

    def _settled_after(self, cmd: str, **fields: Any) -> Record:
        """Carry out ``cmd`` (:meth:`_call`), then wait until the platform settles (:meth:`wait_settled`)."""
        self._call(cmd, **fields)
        return self.wait_settled(0.0)

    def tell(self, progress: dict[str, Any]) -> None:
        """Hand the campaign's progress to the service for its displays (``progress``); a
        service that does not take it (an older one) or does not answer is not the
        campaign's concern: its next command finds out."""
        with contextlib.suppress(ServiceUnavailable):
            self.client.request("progress", **progress)

    def _call(self, cmd: str, harmless: tuple[str, ...] = (), **fields: Any) -> dict[str, Any]:
        """Carry out ``cmd``; a refusal ends the campaign unless its code is ``harmless`` ({} then)."""
        attempts = 1
        while True:
            try:
                return self.client.call(cmd, **fields)
            except CommandError as error:
                self._latched(error)
                if error.code in harmless:
                    return {}
                if error.code != "expired":
                    raise CampaignError(f"the controller refused {cmd}: {error}") from None
                if attempts == MOVE_ATTEMPTS:
                    raise CampaignError(f"the controller refused {cmd}: {error} (the host is too loaded for the "
                                        "command timeout: raise --timeout)") from None
                attempts += 1  # not carried out: asking again cannot do it twice

    def _latched(self, error: CommandError) -> None:
        """A refusal because a fault latched meanwhile is that fault (:class:`ControllerFault`)."""
        if error.code == "latched":
            self.status()


def _heard(record: Record) -> bool:
    feedback = record["leg_feedback"]
    return feedback is not None and all(value is not None for value in feedback)


def _current(record: Record) -> bool:
    """Whether the record is the loop's present state: it has reported within
    :data:`~hexactl.control.results.REPORT_SILENT_S` (else the last report of a loop
    held up or stopped)."""
    return record["loop"]["report_age_s"] <= REPORT_SILENT_S


def _moved(a: Record, b: Record) -> float:
    return max(abs(x - y) for x, y in zip(a["leg_feedback"], b["leg_feedback"]))
