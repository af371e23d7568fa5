"""The front-end (paper Secs. III-C to III-E): odometry, detection, observations, adaptive clips,
registration, refinement, and the streaming front-end that places clips."""
