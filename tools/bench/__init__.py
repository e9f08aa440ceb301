"""Benchmarks (latency, simulator, training) and the random-weight networks they and the tests drive."""
