"""The controllers: PID, LQR with integral action, feedback linearisation, lead-lag,
each ending in the actuator command.  They import plants at most."""
