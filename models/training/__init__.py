"""A training run: its configuration and recipe, the loop, distributed training, metrics, its files and record."""
