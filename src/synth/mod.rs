//! Synthetic scans with known truth: ellipsoid caps, Gaussian random surfaces, tilted planes.
