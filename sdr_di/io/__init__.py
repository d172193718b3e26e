"""File formats: IF samples, metadata sidecar, IMU and truth files, atomic writing."""
