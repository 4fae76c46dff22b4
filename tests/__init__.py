"""Test suite of parallel-robot-gym, laid out like the packages it tests."""
