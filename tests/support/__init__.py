"""Helpers shared by the tests: real data lookup, synthetic rides, ROS processes, MCAP readers
and the hairpin fixtures (registered for every test by the root conftest)."""
