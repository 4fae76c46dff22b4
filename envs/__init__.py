"""Gymnasium environments for parallel robots (registration lives here)."""
