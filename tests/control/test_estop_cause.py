"""Each E-stop the controller sends says why (the actuators log it): an operator's, an
actuator's e-stop input, another controller on the bus; and every repeat of it says the
same. (The loop's crash: tests/control/test_loop_thread.py.)"""

from __future__ import annotations

from hexactl.control.hardware import BusState, EstopCause, LinkHealth


def _repeats(rig) -> None:
    """Run until the E-stop has been repeated once (every 100 ms while it lasts)."""
    sent = rig.actuators.estops
    rig.run_until(lambda: rig.actuators.estops > sent)


def test_an_operators_estop_says_operator(rig):
    rig.enabled()
    rig.controller.estop()
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    assert rig.actuators.last_estop_cause is EstopCause.OPERATOR
    _repeats(rig)
    assert rig.actuators.last_estop_cause is EstopCause.OPERATOR


def test_an_actuators_estop_input_says_safety_chain_and_its_repeats_too(rig):
    """It said OPERATOR: an actuator's log blamed a person for its own e-stop input."""
    rig.enabled()
    rig.actuators.press_estop()  # an actuator's e-stop input opened
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    assert rig.actuators.last_estop_cause is EstopCause.SAFETY_CHAIN
    _repeats(rig)
    assert rig.actuators.last_estop_cause is EstopCause.SAFETY_CHAIN


def test_another_controller_on_the_bus_says_controller_fault(rig):
    rig.enabled()
    rig.actuators.link_health = lambda: LinkHealth(BusState.ACTIVE, 0, other_controller_age_s=0.0,
                                                   other_controller_frame="SETPOINT_12")
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    assert rig.actuators.last_estop_cause is EstopCause.CONTROLLER_FAULT
    _repeats(rig)
    assert rig.actuators.last_estop_cause is EstopCause.CONTROLLER_FAULT
