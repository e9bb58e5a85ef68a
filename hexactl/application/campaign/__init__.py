"""The calibration campaign driven through a running controller's API (``hexactl
campaign``, and ``hexactl demo`` on an in-process service): :mod:`.runner` runs it,
:mod:`.driver` moves the platform, :mod:`.instruments` measures it, :mod:`.store` saves
every measurement as it is taken, :mod:`.progress` reports."""
