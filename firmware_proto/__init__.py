"""The hexapod actuator CAN protocol.

``hexapod.dbc`` is the single source of truth; ``PROTOCOL.md`` explains it,
:mod:`firmware_proto.codec` is the fast Python codec for the control loop,
:mod:`firmware_proto.busload` computes the bus-load budget and ``generated/``
holds the firmware's C code (regenerate with ``python -m firmware_proto.generate``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import cantools.database

DBC_PATH = Path(__file__).with_name("hexapod.dbc")


def load_database() -> cantools.database.can.Database:
    """Load ``hexapod.dbc`` with cantools' strict consistency checks.

    :raises cantools.database.UnsupportedDatabaseFormatError: if the DBC is malformed or inconsistent.
    """
    # Imported here so that control-loop code importing only the codec does not pay for cantools.
    import cantools.database

    return cantools.database.load_file(DBC_PATH, strict=True)
