"""Calibration: identify a platform's structural parameters from measured postures.

Pure mathematics, no file I/O and no printing (files, reports and the command line are
adapters). The pieces follow a campaign's steps so a controller-driven campaign can reuse
them one by one:

plan (:mod:`.planning`) → drive and measure (the controller, in the order and along
the paths of :mod:`.campaign`; or :mod:`hexactl.sim.offline_campaign`) → rows
(:mod:`.data`) → identify (:mod:`.identification`) → validate (:mod:`.test_motions`,
:mod:`.validation`, :mod:`.uncertainty`).
"""
