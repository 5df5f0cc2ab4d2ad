"""The plants: physical models of the levitated bodies with their actuators and sensors.

One module per rig of a source paper, SI units; plants import nothing else of the lab."""
