"""Validation: block-diagram simulation, scenarios, reproduction of the paper."""
