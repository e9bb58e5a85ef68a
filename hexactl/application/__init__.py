"""The application layer: what composes the control loop, the simulator and the adapters
into the things a user runs. ``hexactl serve`` (:mod:`.service`: the loop's process;
:mod:`.api_process`: the API's; :mod:`.loop_link`: what crosses between them;
:mod:`.spawned`: the child processes; :mod:`.simulator`: the built-in simulator), the
calibration campaign (:mod:`.campaign`) and ``hexactl demo`` (:mod:`.demo`)."""
