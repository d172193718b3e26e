"""Simulation: trajectory truth, IMU model, signal geometry and the IF generator."""
