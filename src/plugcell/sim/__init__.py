"""plugcell.sim — everything simulated, behind the seams a real device plugs into.

* :mod:`.twin` — the digital twin: the hidden true robot (geometry, compliance,
  thermal drift, noise), the laser tracker model, measurement campaigns;
* :mod:`.controller` — the simulated robot controller (program runner, arm, the
  T-MAC's true pose for the simulated tracker);
* :mod:`.drivers` — simulated instruments behind the device services' driver
  interfaces (camera, drill, laser tracker);
* :mod:`.world` — the sim-only key space the simulated devices share physical facts on;
* :mod:`.twin_cell` — one twin robot and tracker as in-process devices implementing
  :mod:`plugcell.compensation.protocols` (thesis 8.3 without services).

Service logic never knows whether its driver is simulated.
"""
