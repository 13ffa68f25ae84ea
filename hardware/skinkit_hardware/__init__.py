"""skinkit's microrobot hardware layer: kinematics, drivers, device emulator, wire protocols."""
