"""A run's streaming plumbing: readings spilled to disk, reordered and read back in bounded memory."""
