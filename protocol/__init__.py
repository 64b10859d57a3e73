"""The rig protocol: what the PLC and the sensors say on the wire, declared once for both ends.

`plc` (states, commands, faults, safety limits, setpoint and status names), `modbus` (the register map),
`ads` (the PLC symbols), `frames` (the accelerometer stream), `can_frames` (accelerometers on CAN),
`sweep` (the table's sweep profile, which the PLC runs and the DAQ checks). The simulated rig (sim/)
serves it and the DAQ (daq/) speaks it; this package imports neither (numpy only), so a DAQ client
never loads the simulator. Tables: docs/rig-protocols.md.
"""

#: The wire protocols the PLC is reached by, a rig configuration's [plc] transport (the first is the default):
#: `modbus` (the register map) and `ads` (the symbols). The DAQ has one backend per name (daq.plc.BACKENDS).
PLC_TRANSPORTS = ("modbus", "ads")
#: Where the DAQ reads the accelerometers, a rig configuration's [sampling] source and the section that
#: configures it (the first is the default): `stream` (the framed stream, `frames`) and `can` (`can_frames`).
#: The DAQ has one source class per name (daq.sources.SOURCES).
ACCELEROMETER_SOURCES = ("stream", "can")
