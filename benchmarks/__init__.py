"""Benchmarks of parallel-robot-gym, runnable as modules (python -m benchmarks.<name>)."""
