"""Kinetostatic ANCF model of bellow-shaped pneumatic soft continuum robots."""

__version__ = '0.1.0'
