"""Experiments that produce the docs' tables and pictures: the main job (demo), surveys and reports.

They use ``training`` (evaluation, distillation) and ``robot_control`` (the baselines); nothing imports them.
"""
