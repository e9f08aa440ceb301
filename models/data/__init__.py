"""Training data: reading logs into samples, labels, balancing, the split, the frame cache and batches."""
