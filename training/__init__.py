"""Stable-Baselines3 training and headless evaluation for the parallel-robot environments."""
