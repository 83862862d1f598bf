"""plugcell.sim.controller — the simulated robot controller.

It runs programs in the robot language (:mod:`plugcell.pdl`; the program library is
``plugcell/pdl/programs``) with the program runner
(:mod:`plugcell.devices.robot.runner`, the same one a PC uses for a real robot) on a
simulated arm (:mod:`.arm`: the twin at each target at once, or with ``--dynamics`` the
dynamic twin moving in time), speaks the
robot service's controller protocol (:mod:`plugcell.devices.robot.protocol`) over TCP or
a serial line, and publishes its T-MAC's true pose for the simulated tracker
(:mod:`.reflector`).  The twin's real-time robot sides — KUKA RSI (:mod:`.rsi_robot`) and
ABB EGM (:mod:`.egm_robot`) — stand where a vendor's controller stands (``plugcell twin
rsi``, ``plugcell twin egm``).
"""
