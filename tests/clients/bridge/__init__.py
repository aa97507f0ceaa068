"""Tests of the hardware bridge."""
