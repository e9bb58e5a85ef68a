"""Test-wide set-up: each test in a working directory of its own, and vcan test selection
(see tools/uml_vcan.py).

* ``vcan``-marked tests need a real SocketCAN ``vcan0``.  Where it exists (inside
  the user-mode Linux guest, or a developer box with vcan0 up) they run as
  usual.  Where it does not, they are *deselected* at collection, not skipped:
  ``tests/test_vcan_in_uml.py`` runs them inside UML instead.
* Tests marked ``uml_runner`` (that UML launcher test) are deselected where
  vcan0 exists or inside the guest (``HEXACTL_IN_UML=1``), so nothing recurses
  and nothing runs twice.
"""

import os

import pytest
from hypothesis import settings

# Hypothesis's default 200 ms deadline per example is a wall-clock limit: on a shared, busy
# host one slow example fails a correct test (codec round trips did). Properties are checked
# here, not speed; speed is measured in BENCHMARKS.md.
settings.register_profile("hexactl", deadline=None)
settings.load_profile("hexactl")


HAS_VCAN0 = os.path.exists("/sys/class/net/vcan0")
IN_UML = os.environ.get("HEXACTL_IN_UML") == "1"

MACHINE_SETTINGS = ("HEXACTL_CONFIG", "HEXACTL_API", "HEXACTL_TELEMETRY", "HEXACTL_CURVE_SERVER",
                    "HEXACTL_CURVE_CLIENT", "HEXACTL_CLIENT_CONFIG")
"""What an operator's shell gives the hexactl commands (README, "Command line"): the tests'
geometry, services and clients are their own whatever the machine running them has set.
Removed here, before test modules load the geometry and fixtures start processes."""
for _setting in MACHINE_SETTINGS:
    os.environ.pop(_setting, None)


@pytest.fixture(autouse=True, scope="session")
def _session_working_directory(tmp_path_factory):
    """Fixtures wider than a test (a module's service) start in a working directory of the
    session's, not in the checkout: a service writes ./frames.toml, ./recordings, … there."""
    before = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("session-cwd"))
    yield
    os.chdir(before)


@pytest.fixture(autouse=True, scope="session")
def _no_client_file_of_the_machine(tmp_path_factory):
    """The client file is read from $XDG_CONFIG_HOME (else ~/.config): an empty one of the
    session's, not the operator's (cli/endpoints.py)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.mktemp("xdg-config")))
        yield


@pytest.fixture(autouse=True, scope="module")
def _module_working_directory(tmp_path_factory):
    """A module's own fixtures (its service) start in a working directory of the module's:
    what one module's service keeps there (./frames.toml, ./active_calibration.toml) is
    not another module's service's start."""
    before = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("module-cwd"))
    yield
    os.chdir(before)


@pytest.fixture(autouse=True)
def _working_directory(tmp_path_factory, monkeypatch):
    """Each test runs in an empty working directory of its own: a service started with its
    default data directories creates ./recordings, ./calibrations and ./sequences there,
    not in the checkout, and no test sees another's files."""
    monkeypatch.chdir(tmp_path_factory.mktemp("cwd"))


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "uml_runner: runs the vcan tests inside user-mode Linux (host without vcan0 only)")


def pytest_report_header(config):
    where = "inside UML" if IN_UML else ("host" if HAS_VCAN0 else "host without vcan0")
    plan = "run here" if HAS_VCAN0 else "run inside UML by tests/test_vcan_in_uml.py"
    return f"hexactl vcan: {where}; vcan-marked tests {plan}"


def pytest_collection_modifyitems(config, items):
    def unwanted(item):
        if item.get_closest_marker("vcan") is not None:
            return not HAS_VCAN0
        if item.get_closest_marker("uml_runner") is not None:
            return HAS_VCAN0 or IN_UML
        return False

    drop = [item for item in items if unwanted(item)]
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = [item for item in items if not unwanted(item)]
