"""Each E-stop the controller sends says why (the actuators log it): an operator's, an
actuator's e-stop input, another controller on the bus; and every repeat of it says the
same. (The loop's crash: tests/control/test_loop_thread.py.)"""

from __future__ import annotations

from hexactl.control.hardware import BusState, EstopCause, LinkHealth


def _ends_in_estop_saying(rig, cause: EstopCause) -> None:
    """One cycle latches ESTOP and sends it with ``cause``; its repeat (every 100 ms while it
    lasts) says the same."""
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    assert rig.actuators.last_estop_cause is cause
    sent = rig.actuators.estops
    rig.run_until(lambda: rig.actuators.estops > sent)
    assert rig.actuators.last_estop_cause is cause


def test_an_operators_estop_says_operator(rig):
    rig.enabled()
    rig.controller.estop()
    _ends_in_estop_saying(rig, EstopCause.OPERATOR)


def test_an_actuators_estop_input_says_safety_chain(rig):
    """It said OPERATOR: an actuator's log blamed a person for its own e-stop input."""
    rig.enabled()
    rig.actuators.press_estop()  # an actuator's e-stop input opened
    _ends_in_estop_saying(rig, EstopCause.SAFETY_CHAIN)


def test_another_controller_on_the_bus_says_controller_fault(rig):
    rig.enabled()
    rig.actuators.link_health = lambda: LinkHealth(BusState.ACTIVE, 0, other_controller_age_s=0.0,
                                                   other_controller_frame="SETPOINT_12")
    _ends_in_estop_saying(rig, EstopCause.CONTROLLER_FAULT)
