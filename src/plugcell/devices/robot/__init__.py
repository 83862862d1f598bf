"""The robot service (thesis 7.2, Table 7-1): the robot's program drives the cell.

* :mod:`.service` — ``RobotService``: the catalogue of Table 7-1, the controller link;
* :mod:`.outbound` — the ExternalProcessHandler: processes a program asks of partners;
* :mod:`.data` — the Data field of an ACTIVATE string ↔ typed process data;
* :mod:`.increment` — the corrective joint increment δθ = J⁻¹·Δx (thesis 8.3.2);
* :mod:`.sim_launcher` — starts and stops the simulated controller of a ``--sim`` robot;
* ``python -m plugcell.devices.robot`` — the legacy entry (``__main__``).
"""
