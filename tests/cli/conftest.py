"""Fixtures of the command-line tests: a service on the simulator and a client of it, as
the API's service tests have them (``running``, ``client``)."""

from tests.api.conftest import data_dir, running  # noqa: F401 - fixtures shared with tests/api
from tests.api.test_service import client  # noqa: F401
