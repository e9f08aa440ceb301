"""The paper's augmentations and the turned camera: the literal reference and the one-warp fast path."""
