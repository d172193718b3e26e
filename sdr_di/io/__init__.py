"""File formats: IF samples, metadata sidecar, peers' tags, SigMF recordings, IMU and truth files,
atomic writing."""
