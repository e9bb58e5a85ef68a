"""Where the geometry file is when a command names none.

Standard library only, so that the command line can name the variable in its help
without loading the geometry's numpy; reading the file is :mod:`~hexactl.adapters.files.geometry_file`.
"""

from __future__ import annotations

import os
from pathlib import Path

CONFIG_ENVIRONMENT_VARIABLE = "HEXACTL_CONFIG"
DEFAULT_CONFIG = Path("config") / "platform.toml"
_REPOSITORY_CONFIG = Path(__file__).resolve().parents[3] / DEFAULT_CONFIG


def default_config_path() -> Path:
    """The geometry used when none is named: $HEXACTL_CONFIG, else ./config/platform.toml,
    else the repository's config/platform.toml (for commands run outside the checkout)."""
    from_environment = os.environ.get(CONFIG_ENVIRONMENT_VARIABLE)
    if from_environment:
        return Path(from_environment)
    return DEFAULT_CONFIG if DEFAULT_CONFIG.exists() else _REPOSITORY_CONFIG


SHIPPED_VEHICLES = _REPOSITORY_CONFIG.parent / "vehicles"
"""The vehicle trajectories hexactl ships (``hexactl cue braking``)."""
