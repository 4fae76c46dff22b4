"""Tests of the Gymnasium environments (``envs``)."""
