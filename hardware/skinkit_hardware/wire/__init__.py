"""Wire protocols: the serial framing (``serial_codec``), the CAN messages (``can_codec``,
``skinkit_robot.dbc``) and the sensor-count encoding both share (``counts``)."""
