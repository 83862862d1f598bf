"""plugcell.devices — the device services, one module or sub-package per family.

* :mod:`.camera`, :mod:`.drill` — the camera and the drill (thesis 5.1–5.2);
* :mod:`.robot` — the robot service and its controller link (protocol, bridge, framing);
* :mod:`.tracker` — the laser tracker service (requesters' frames, drivers, routing);
* :mod:`.compute` — the compute service (workspace, expressions, functions);
* :mod:`.cell` — the cell controller (wiring, tasks, runs, monitor, UI feed);
* :mod:`.opcua` — the OPC UA gateway and the OPC UA device service;
* the kinds ``plugcell serve KIND`` knows are in :mod:`plugcell.apps.kinds`.

Each is a device class — a :class:`~plugcell.framework.declaration.Declaration` and a
``dispatch`` in front of the driver of its family — which a
:class:`plugcell.framework.service.GenericDevice` hosts (composed, not derived).
"""
