"""Rig calibration maths: pure functions on captured arrays, no devices."""
