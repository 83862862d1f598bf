"""The robot service (thesis 7.2, Table 7-1): the robot's program drives the cell.

* :mod:`.service` — ``RobotService``: the catalogue of Table 7-1, the controller link;
* :mod:`.outbound` — the ExternalProcessHandler: processes a program asks of partners;
* :mod:`.data` — the Data field of an ACTIVATE string ↔ typed process data;
* :mod:`.increment` — the corrective joint increment δθ = J⁻¹·Δx (thesis 8.3.2);
* the controller link: :mod:`.protocol` (the line protocol's messages), :mod:`.framing`
  and :mod:`.serial_line` (lines over TCP or a serial port), :mod:`.bridge` (the
  service's end, asyncio), :mod:`.activate` (the ACTIVATE string), :mod:`.value_text`
  (a value's protocol text), :mod:`.poses` (robot poses in mm and degrees ↔ 4×4);
* a ``--sim`` robot's simulated controller is started by
  :mod:`plugcell.sim.controller.launcher`;
* ``python -m plugcell.devices.robot`` — the legacy entry (``__main__``).
"""
