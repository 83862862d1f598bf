"""plugcell.opcua — the cell in OPC UA (IEC 62541), both ways (docs/opcua.md).

* :mod:`.gateway` — ``plugcell opcua serve``: an OPC UA server mirroring the cell
  (services as objects, commands as methods, processes as objects and events);
* :mod:`.address_space` — the nodes of that server;
* :mod:`.arguments` — process data ↔ OPC UA variants and method arguments;
* :mod:`.users` — the gateway's username/password users.

Built on asyncua and only the framework's public client API.
"""
