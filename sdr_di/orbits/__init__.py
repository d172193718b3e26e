"""Broadcast ephemerides, satellite orbits and clocks, precise orbits, atmosphere models."""
