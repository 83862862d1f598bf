"""plugcell.devices.opcua — the cell in OPC UA (IEC 62541), both ways (docs/opcua.md).

* :mod:`.gateway` — ``plugcell opcua serve``: an OPC UA server mirroring the cell
  (services as objects, commands as methods, processes as objects and events);
  :mod:`.method_calls` — its method calls, each a process sent as the OPC UA user;
* :mod:`.address_space` — the nodes of that server; :mod:`.companion` — the DI and OPC
  40010 NodeSets (``nodesets/``) and the services as typed devices in ``DeviceSet``;
  :mod:`.robots` — robots as OPC 40010 ``MotionDeviceSystemType``;
* :mod:`.arguments` — process data ↔ OPC UA variants and method arguments;
* :mod:`.server_security`, :mod:`.users`, :mod:`.certificates` — the gateway's
  policies, its username/password users, the cell's OPC UA certificates;
* :mod:`.sessions` — which session and user a method call comes from;
* :mod:`.device_map`, :mod:`.device` — ``plugcell serve opcua-device``: an OPC UA
  server's device as a plugcell service; :mod:`.server_trust` — which servers it
  trusts (their certificates checked).

Built on asyncua and only the framework's public client API.
"""
