"""Tests of the training layer: configuration, training runs, evaluation, controllers and the demo."""
