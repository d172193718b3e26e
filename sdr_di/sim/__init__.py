"""Simulation: trajectory truth, IMU model, signal geometry, the truth atmosphere
(:mod:`~sdr_di.sim.atmosphere`) and the IF generator."""
