"""The MES face: an OPC UA server per the Robotics companion specification (OPC 40010-1).

``service.PendantOpcUa`` serves, ``space`` builds the address space, ``state`` reads what
it shows from the database. The official DI and Robotics nodesets ship in ``nodesets/``.
"""
