"""Motion cueing: a vehicle's specific force and angular rate to platform poses.

Pure math (numpy and scipy; no file, clock or I/O, an import-linter contract): the
parameters (:mod:`~hexactl.cueing.parameters`), the classical washout filter
(:mod:`~hexactl.cueing.washout`) and the fitting of its output into the workspace
(:mod:`~hexactl.cueing.workspace_gain`). :mod:`hexactl.application.cueing` composes them
into a plan; docs/cueing.md explains the filter and each parameter.
"""
